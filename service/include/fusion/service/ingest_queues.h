// Bounded per-sensor queues between the DDS ingest thread and the fusion worker, with the
// ingest counters every layer updates. Newest wins: a full queue drops its oldest cloud
// (sensor data, best effort). With reliable ingest, Push waits for room instead, so a
// reliable stream (a replayed recording) loses nothing and DDS flow control slows its writer.
#pragma once

#include <array>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "fusion/service/cloud.h"

namespace fusion::service {

struct RejectCounters {
  std::array<std::atomic<std::uint64_t>, kRejectReasonCount> by_reason{};
  void Count(RejectReason reason) {
    by_reason[static_cast<std::size_t>(reason)].fetch_add(1, std::memory_order_relaxed);
  }
  [[nodiscard]] std::uint64_t Total() const;
};

struct SensorCountersAtomic {
  std::atomic<std::uint64_t> received{0};  // valid clouds queued
  std::atomic<std::uint64_t> dropped{0};   // replaced by a newer cloud before integration
  std::atomic<std::uint64_t> integrated{0};
  std::atomic<std::uint64_t> merged{0};    // integrated into an open period from beyond its pose
                                           // tolerance (the renderer was behind)
  std::atomic<std::uint64_t> changes_detected{0};  // beams restarted: the world changed
  std::atomic<std::uint64_t> points_updated{0};
  std::atomic<std::uint64_t> points_beyond_range{0};
  std::atomic<std::uint64_t> points_missing{0};
  std::atomic<std::uint64_t> points_rejected{0};
  std::atomic<std::uint64_t> last_sequence_number{0};
  std::atomic<std::uint64_t> memory_bytes{0};
  RejectCounters rejected;
};

// DDS writers matched with the points reader (the DDS ingest updates them).
struct MatchedWriters {
  std::atomic<std::uint32_t> current{0};
  std::atomic<std::uint64_t> total{0};  // since the start
};

class IngestQueues {
 public:
  // (sensor id, queue depth >= 1) for every configured sensor. The queues together hold at
  // most `max_queued_bytes` of clouds (0: no bound), plus one cloud per sensor: a sensor with
  // an empty queue may always queue one.
  explicit IngestQueues(const std::vector<std::pair<std::string, std::size_t>>& sensors,
                        std::size_t max_queued_bytes = 0);

  [[nodiscard]] bool Known(const std::string& sensor_id) const;
  [[nodiscard]] std::vector<std::string> SensorIds() const;
  // nullptr for an unknown id.
  [[nodiscard]] SensorCountersAtomic* counters(const std::string& sensor_id);
  [[nodiscard]] const SensorCountersAtomic* counters(const std::string& sensor_id) const;
  // Rejections of every sample, whatever its sensor id (known or not).
  [[nodiscard]] RejectCounters& all_rejected() { return all_rejected_; }
  [[nodiscard]] const RejectCounters& all_rejected() const { return all_rejected_; }
  void CountRejected(const std::string& sensor_id, RejectReason reason);
  [[nodiscard]] MatchedWriters& matched_writers() { return matched_writers_; }
  [[nodiscard]] const MatchedWriters& matched_writers() const { return matched_writers_; }

  // Queues a validated cloud of a known sensor. With `stop` null, a full queue (its depth, or
  // the byte bound) drops its oldest cloud (counted). Otherwise Push waits while it is full;
  // it returns false (the cloud not queued, counted as dropped) if *stop becomes true while
  // it waits.
  bool Push(Cloud cloud, const std::atomic<bool>* stop = nullptr);
  // Moves every queued cloud into *out (oldest first per sensor). Waits until there is one,
  // Wake() is called or `until` passes. Returns true if *out is non-empty.
  bool PopAll(std::vector<Cloud>* out, std::chrono::steady_clock::time_point until);
  void Wake();
  [[nodiscard]] std::size_t Pending() const;
  // Clouds queued for one sensor (0 for an unknown id).
  [[nodiscard]] std::size_t Pending(const std::string& sensor_id) const;
  [[nodiscard]] std::size_t queued_bytes() const;
  // What a cloud costs the byte bound: its points and flags.
  [[nodiscard]] static std::size_t BytesOf(const Cloud& cloud);

 private:
  struct Slot {
    std::size_t depth = 1;
    std::deque<Cloud> queue;
    SensorCountersAtomic counters;
  };
  [[nodiscard]] bool FullLocked(const Slot& slot, std::size_t bytes) const;

  std::map<std::string, std::unique_ptr<Slot>> slots_;  // fixed after construction
  std::size_t max_queued_bytes_ = 0;
  std::size_t queued_bytes_ = 0;  // under mutex_
  RejectCounters all_rejected_;
  MatchedWriters matched_writers_;
  mutable std::mutex mutex_;
  std::condition_variable cv_;        // clouds queued (or Wake)
  std::condition_variable space_cv_;  // clouds taken
  bool woken_ = false;
};

}  // namespace fusion::service
