#include "fusion/service/admission.h"

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

void LowerThreadPriorityOnce(int nice) {
  thread_local bool done = false;
  if (done) return;
  done = true;
  // Linux: the nice value of one thread (PRIO_PROCESS with a thread id).
  const auto tid = static_cast<id_t>(::syscall(SYS_gettid));
  (void)::setpriority(PRIO_PROCESS, tid, nice);
}

}  // namespace fusion::service
