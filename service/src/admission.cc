#include "fusion/service/admission.h"

#include <malloc.h>
#include <sched.h>
#include <sys/resource.h>
#include <sys/syscall.h>
#include <unistd.h>

namespace fusion::service {

std::optional<CountedSlot> CountedSlot::Take(std::atomic<std::uint32_t>* count,
                                             std::uint32_t limit) {
  if (count->fetch_add(1) >= limit) {
    count->fetch_sub(1);
    return std::nullopt;
  }
  return CountedSlot(count);
}

CountedSlot::~CountedSlot() {
  if (count_ != nullptr) count_->fetch_sub(1);
}

bool IngestPressure::Behind(const IngestQueues& queues, std::chrono::steady_clock::time_point now) {
  std::lock_guard<std::mutex> lock(mutex_);
  if (!watching_ || now - checked_ >= kPoll) {
    std::uint64_t dropped = 0;
    for (const std::string& id : queues.SensorIds()) dropped += queues.counters(id)->dropped.load();
    // The first reading is the baseline: drops before anyone asked do not count.
    if (watching_ && dropped > dropped_) {
      last_drop_ = now;
      dropped_recently_ = true;
    }
    watching_ = true;
    checked_ = now;
    dropped_ = dropped;
  }
  return dropped_recently_ && now - last_drop_ < kWindow;
}

QueryPool::QueryPool(std::size_t threads, int nice, std::function<void()> after_task)
    : after_task_(std::move(after_task)) {
  for (std::size_t i = 0; i < threads; ++i) threads_.emplace_back([this, nice] { Run(nice); });
}

QueryPool::~QueryPool() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stopping_ = true;
  }
  cv_.notify_all();
  for (auto& t : threads_) t.join();
}

void QueryPool::Post(std::function<void()> task) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    tasks_.push_back(std::move(task));
  }
  cv_.notify_one();
}

void QueryPool::Run(int nice) {
  (void)SetBackgroundPriority(nice);
  for (;;) {
    std::function<void()> task;
    {
      std::unique_lock<std::mutex> lock(mutex_);
      cv_.wait(lock, [this] { return stopping_ || !tasks_.empty(); });
      if (tasks_.empty()) return;  // stopping, and nothing left to run
      task = std::move(tasks_.front());
      tasks_.pop_front();
    }
    task();
    task = nullptr;  // its captures are freed before after_task runs
    if (after_task_) after_task_();
  }
}

bool HeapTrimmer::MaybeTrim(std::chrono::steady_clock::time_point now) {
  std::unique_lock<std::mutex> lock(mutex_, std::try_to_lock);
  if (!lock.owns_lock() || (trimmed_ && now - last_ < min_interval_)) return false;
  trimmed_ = true;
  last_ = now;
  ::malloc_trim(0);
  return true;
}

namespace {

// The kernel's struct sched_attr, its first version (SCHED_ATTR_SIZE_VER0, 48 bytes): glibc has
// no sched_setattr, and <linux/sched/types.h> cannot be included beside <sched.h>.
struct SchedAttr {
  std::uint32_t size, policy;
  std::uint64_t flags;
  std::int32_t nice;
  std::uint32_t priority;
  std::uint64_t runtime_ns, deadline_ns, period_ns;
};
static_assert(sizeof(SchedAttr) == 48);

// The shortest time slice a fair thread may ask for (Linux 6.12 clamps to 0.1-100 ms).
constexpr std::uint64_t kBackgroundSliceNs = 100'000;

}  // namespace

bool SetBackgroundPriority(int nice) {
  const int policy = ::sched_getscheduler(0);
  if (policy == SCHED_OTHER || policy == SCHED_BATCH) {
    SchedAttr attr{};
    attr.size = sizeof attr;
    attr.policy = static_cast<std::uint32_t>(policy);
    attr.nice = nice;
    attr.runtime_ns = kBackgroundSliceNs;
    if (::syscall(SYS_sched_setattr, 0, &attr, 0) == 0) return true;
  }
  // Refused (a seccomp filter, another policy): the nice value alone.
  const auto tid = static_cast<id_t>(::syscall(SYS_gettid));
  return ::setpriority(PRIO_PROCESS, tid, nice) == 0;
}

std::uint64_t ThisThreadSliceNs() {
  SchedAttr attr{};
  if (::syscall(SYS_sched_getattr, 0, &attr, sizeof attr, 0) != 0) return 0;
  return attr.policy == SCHED_OTHER || attr.policy == SCHED_BATCH ? attr.runtime_ns : 0;
}

}  // namespace fusion::service
