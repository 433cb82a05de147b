// Writes the published map to the configured snapshot file: periodically (when it changed),
// on request and at shutdown. Writes are serialised.
#pragma once

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <mutex>
#include <string>
#include <thread>

#include "fusion/core/status.h"
#include "fusion/service/map_snapshot.h"

namespace fusion::service {

class Persister {
 public:
  // interval 0: no periodic snapshots.
  Persister(std::string path, std::chrono::seconds interval, SnapshotHub* hub);
  ~Persister();
  Persister(const Persister&) = delete;
  Persister& operator=(const Persister&) = delete;

  [[nodiscard]] bool enabled() const { return !path_.empty(); }
  [[nodiscard]] const std::string& path() const { return path_; }
  void Start();
  void Stop();
  // Writes the current snapshot now: *version and *bytes say what was written.
  [[nodiscard]] Status SaveNow(std::uint64_t* version, std::uint64_t* bytes);
  // The version the file on disk holds (loaded or last written); UINT64_MAX for none.
  void set_saved_version(std::uint64_t version);
  [[nodiscard]] std::uint64_t saves() const { return saves_.load(); }
  // Writes that failed, whether the last one did, and its error.
  [[nodiscard]] std::uint64_t failures() const { return failures_.load(); }
  [[nodiscard]] bool failing() const { return failing_.load(); }
  [[nodiscard]] std::string last_error() const;
  // Called (on the writing thread) whenever a write succeeds after failures or fails after
  // successes: true = writes succeed. Set before Start.
  void set_on_health(std::function<void(bool)> on_health) { on_health_ = std::move(on_health); }

 private:
  void Loop();

  std::string path_;
  std::chrono::seconds interval_;
  SnapshotHub* hub_;
  std::mutex write_mutex_;
  std::uint64_t saved_version_ = UINT64_MAX;
  std::atomic<std::uint64_t> saves_{0};
  std::atomic<std::uint64_t> failures_{0};
  std::atomic<bool> failing_{false};
  mutable std::mutex error_mutex_;
  std::string last_error_;
  std::function<void(bool)> on_health_;
  std::mutex stop_mutex_;
  std::condition_variable stop_cv_;
  bool stop_ = false;
  std::thread thread_;
};

}  // namespace fusion::service
