// Admission of queries under load (docs/service.md, "Overload"): a bounded number of
// expensive calls at once, none while ingest is dropping clouds, and query threads at a lower
// priority than the fusion worker. Clouds are never shed for queries; queries are shed first.
#pragma once

#include <atomic>
#include <chrono>
#include <cstdint>
#include <mutex>
#include <optional>
#include <utility>

#include "fusion/service/ingest_queues.h"

namespace fusion::service {

// One of `limit` slots of a counter, held until destroyed.
class CountedSlot {
 public:
  // nullopt if `limit` slots are held already.
  static std::optional<CountedSlot> Take(std::atomic<std::uint32_t>* count, std::uint32_t limit);
  CountedSlot(CountedSlot&& other) noexcept : count_(other.count_) { other.count_ = nullptr; }
  CountedSlot& operator=(CountedSlot&& other) noexcept {
    std::swap(count_, other.count_);
    return *this;
  }
  CountedSlot(const CountedSlot&) = delete;
  ~CountedSlot();

 private:
  explicit CountedSlot(std::atomic<std::uint32_t>* count) : count_(count) {}
  std::atomic<std::uint32_t>* count_;
};

// Whether ingest is losing clouds: some sensor's `dropped` counter grew within the last
// kWindow (the counters are read at most every kPoll).
class IngestPressure {
 public:
  static constexpr std::chrono::milliseconds kWindow{1000};
  static constexpr std::chrono::milliseconds kPoll{100};

  [[nodiscard]] bool Behind(const IngestQueues& queues, std::chrono::steady_clock::time_point now);

 private:
  std::mutex mutex_;
  std::chrono::steady_clock::time_point checked_{};
  std::chrono::steady_clock::time_point last_drop_{};
  std::uint64_t dropped_ = 0;
  bool watching_ = false;
  bool dropped_recently_ = false;
};

// Sets the calling thread's nice value once (later calls on the same thread do nothing).
void LowerThreadPriorityOnce(int nice);

}  // namespace fusion::service
