// Immutable map versions published by the fusion worker and read by the gRPC handlers: a
// handler takes the current pointer under a short lock and reads it while the worker goes on.
#pragma once

#include <octomap/OcTree.h>

#include <cstdint>
#include <deque>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <vector>

namespace fusion::service {

struct MapSnapshot {
  std::uint64_t version = 0;
  std::shared_ptr<const octomap::OcTree> tree;  // never null
};

class SnapshotHub {
 public:
  // Bounds of the change log: older entries are forgotten (subscribers then get the full map).
  static constexpr std::size_t kDefaultMaxLoggedKeys = 4'000'000;
  // Until the first Publish, Current() is an empty map of resolution_m.
  explicit SnapshotHub(std::size_t max_logged_keys = kDefaultMaxLoggedKeys,
                       double resolution_m = 0.05);

  [[nodiscard]] std::shared_ptr<const MapSnapshot> Current() const;
  // Publishes a new version. `changed` are the keys whose value changed since the previous
  // version; `reset` says the previous versions are gone (log cleared).
  void Publish(std::shared_ptr<const MapSnapshot> snapshot, std::vector<octomap::OcTreeKey> changed,
               bool reset);
  // Keys changed after `since` up to the current version (deduplicated). False if the log
  // does not reach back to `since` (the caller then sends the whole map).
  bool ChangedSince(std::uint64_t since, std::vector<octomap::OcTreeKey>* keys) const;

  // Subscribers are called (on the publishing thread, without locks held by the caller) after
  // every Publish and once on Close; they must be quick and must not call Unsubscribe.
  int Subscribe(std::function<void()> callback);
  void Unsubscribe(int id);
  // No more versions will come (shutdown).
  void Close();
  [[nodiscard]] bool closed() const;

 private:
  void Notify();

  mutable std::mutex mutex_;
  std::shared_ptr<const MapSnapshot> current_;
  struct LogEntry {
    std::uint64_t version;
    std::vector<octomap::OcTreeKey> keys;
  };
  std::deque<LogEntry> log_;
  std::uint64_t log_start_version_ = 0;  // versions after this are fully logged
  std::size_t logged_keys_ = 0;
  std::size_t max_logged_keys_;
  bool closed_ = false;

  std::mutex subscribers_mutex_;  // held while calling subscribers
  std::map<int, std::function<void()>> subscribers_;
  int next_id_ = 1;
};

}  // namespace fusion::service
