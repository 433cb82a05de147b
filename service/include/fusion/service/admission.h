// Admission of queries under load (docs/service.md, "Overload"): a bounded number of
// expensive calls at once, none while ingest is dropping clouds, run on threads of a lower
// priority than the fusion worker's. Clouds are never shed for queries; queries are shed first.
#pragma once

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <deque>
#include <functional>
#include <cstdint>
#include <mutex>
#include <optional>
#include <thread>
#include <utility>
#include <vector>

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

// Threads that run the expensive queries at nice `nice` (above the fusion worker's), so that
// however many there are they cannot take the worker's CPU. Admission (CountedSlot) bounds
// what is posted; the destructor runs what is queued, then joins. `after_task` (may be
// empty) runs on the pool thread after each task, once the task and its captures are gone:
// the moment an expensive call's buffers have been freed (fusiond returns them to the OS).
class QueryPool {
 public:
  QueryPool(std::size_t threads, int nice, std::function<void()> after_task = {});
  ~QueryPool();
  QueryPool(const QueryPool&) = delete;
  QueryPool& operator=(const QueryPool&) = delete;
  void Post(std::function<void()> task);

 private:
  void Run(int nice);

  std::mutex mutex_;
  std::condition_variable cv_;
  std::deque<std::function<void()>> tasks_;
  bool stopping_ = false;
  const std::function<void()> after_task_;
  std::vector<std::thread> threads_;
};

// Returns the heap's free memory to the OS (glibc's malloc_trim over every arena), at most
// once per `min_interval`: the expensive calls free tens of megabytes at a time, which the
// allocator would otherwise keep and the RSS would carry. Thread-safe.
class HeapTrimmer {
 public:
  explicit HeapTrimmer(std::chrono::milliseconds min_interval) : min_interval_(min_interval) {}
  // True if it trimmed (false: too soon after the last trim, or another thread is trimming).
  bool MaybeTrim(std::chrono::steady_clock::time_point now);

 private:
  const std::chrono::milliseconds min_interval_;
  std::mutex mutex_;
  std::chrono::steady_clock::time_point last_{};
  bool trimmed_ = false;
};

// Makes the calling thread a background one: its nice value (Linux keeps one per thread) and,
// where the kernel takes it (Linux >= 6.12, EEVDF), the shortest time slice (0.1 ms), so that a
// query thread that wakes runs at once instead of waiting for the slice the running background
// thread was given (up to base_slice, ~1.5-3 ms: what small queries' p99 showed). Older kernels
// ignore the slice. False if the nice value was refused.
bool SetBackgroundPriority(int nice);

// The calling thread's time slice in ns; 0 where the kernel has no per-thread slice (< 6.12).
std::uint64_t ThisThreadSliceNs();

}  // namespace fusion::service
