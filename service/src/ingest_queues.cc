#include "fusion/service/ingest_queues.h"

namespace fusion::service {

std::uint64_t RejectCounters::Total() const {
  std::uint64_t total = 0;
  for (const auto& c : by_reason) total += c.load(std::memory_order_relaxed);
  return total;
}

IngestQueues::IngestQueues(const std::vector<std::pair<std::string, std::size_t>>& sensors,
                           std::size_t max_queued_bytes)
    : max_queued_bytes_(max_queued_bytes) {
  for (const auto& [id, depth] : sensors) {
    auto slot = std::make_unique<Slot>();
    slot->depth = depth < 1 ? 1 : depth;
    slots_.emplace(id, std::move(slot));
  }
}

bool IngestQueues::Known(const std::string& sensor_id) const {
  return slots_.count(sensor_id) != 0;
}

std::vector<std::string> IngestQueues::SensorIds() const {
  std::vector<std::string> ids;
  for (const auto& entry : slots_) ids.push_back(entry.first);
  return ids;
}

SensorCountersAtomic* IngestQueues::counters(const std::string& sensor_id) {
  const auto it = slots_.find(sensor_id);
  return it == slots_.end() ? nullptr : &it->second->counters;
}

const SensorCountersAtomic* IngestQueues::counters(const std::string& sensor_id) const {
  const auto it = slots_.find(sensor_id);
  return it == slots_.end() ? nullptr : &it->second->counters;
}

void IngestQueues::CountRejected(const std::string& sensor_id, RejectReason reason) {
  all_rejected_.Count(reason);
  if (auto* c = counters(sensor_id)) c->rejected.Count(reason);
}

std::size_t IngestQueues::BytesOf(const Cloud& cloud) {
  return cloud.xyz.size() * sizeof(float) + cloud.beyond_range.size();
}

bool IngestQueues::FullLocked(const Slot& slot, std::size_t bytes) const {
  if (slot.queue.size() >= slot.depth) return true;
  return max_queued_bytes_ > 0 && !slot.queue.empty() &&
         queued_bytes_ + bytes > max_queued_bytes_;
}

bool IngestQueues::Push(Cloud cloud, const std::atomic<bool>* stop) {
  const auto it = slots_.find(cloud.sensor_id);
  if (it == slots_.end()) return false;  // callers validate first
  Slot& slot = *it->second;
  const std::size_t bytes = BytesOf(cloud);
  {
    std::unique_lock<std::mutex> lock(mutex_);
    slot.counters.received.fetch_add(1, std::memory_order_relaxed);
    slot.counters.last_sequence_number.store(cloud.sequence_number, std::memory_order_relaxed);
    while (FullLocked(slot, bytes)) {
      if (stop == nullptr) {  // newest wins
        queued_bytes_ -= BytesOf(slot.queue.front());
        slot.queue.pop_front();
        slot.counters.dropped.fetch_add(1, std::memory_order_relaxed);
      } else if (stop->load()) {  // shutting down: give up on this cloud
        slot.counters.dropped.fetch_add(1, std::memory_order_relaxed);
        return false;
      } else {  // wait for the worker to take clouds
        space_cv_.wait_for(lock, std::chrono::milliseconds(100));
      }
    }
    queued_bytes_ += bytes;
    slot.queue.push_back(std::move(cloud));
  }
  cv_.notify_one();
  return true;
}

bool IngestQueues::PopAll(std::vector<Cloud>* out, std::chrono::steady_clock::time_point until) {
  std::unique_lock<std::mutex> lock(mutex_);
  const auto ready = [this] {
    if (woken_) return true;
    for (const auto& entry : slots_) {
      if (!entry.second->queue.empty()) return true;
    }
    return false;
  };
  cv_.wait_until(lock, until, ready);
  woken_ = false;
  for (auto& entry : slots_) {
    for (auto& cloud : entry.second->queue) out->push_back(std::move(cloud));
    entry.second->queue.clear();
  }
  queued_bytes_ = 0;
  lock.unlock();
  space_cv_.notify_all();
  return !out->empty();
}

void IngestQueues::Wake() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    woken_ = true;
  }
  cv_.notify_all();
}

std::size_t IngestQueues::Pending() const {
  std::lock_guard<std::mutex> lock(mutex_);
  std::size_t n = 0;
  for (const auto& entry : slots_) n += entry.second->queue.size();
  return n;
}

std::size_t IngestQueues::Pending(const std::string& sensor_id) const {
  const auto it = slots_.find(sensor_id);
  if (it == slots_.end()) return 0;
  std::lock_guard<std::mutex> lock(mutex_);
  return it->second->queue.size();
}

std::size_t IngestQueues::queued_bytes() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return queued_bytes_;
}

}  // namespace fusion::service
