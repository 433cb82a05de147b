#include "fusion/service/map_snapshot.h"

#include <unordered_set>

namespace fusion::service {

SnapshotHub::SnapshotHub(std::size_t max_logged_keys, double resolution_m)
    : max_logged_keys_(max_logged_keys) {
  auto empty = std::make_shared<MapSnapshot>();
  empty->tree = std::make_shared<octomap::OcTree>(resolution_m);
  current_ = std::move(empty);
  notifier_ = std::thread([this] { NotifierLoop(); });
}

SnapshotHub::~SnapshotHub() {
  {
    std::lock_guard<std::mutex> lock(notify_mutex_);
    stop_notifier_ = true;
  }
  notify_cv_.notify_all();
  notifier_.join();
}

std::shared_ptr<const MapSnapshot> SnapshotHub::Current() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return current_;
}

void SnapshotHub::Publish(std::shared_ptr<const MapSnapshot> snapshot,
                          std::vector<octomap::OcTreeKey> changed, bool reset) {
  // What the hub lets go of is destroyed after the lock is released: freeing an octree of
  // 100 000 nodes takes milliseconds, and every query takes this lock for Current().
  std::shared_ptr<const MapSnapshot> previous_snapshot;
  std::deque<LogEntry> forgotten;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    const std::uint64_t previous = current_->version;
    if (reset) {
      forgotten.swap(log_);
      logged_keys_ = 0;
      log_start_version_ = snapshot->version;
    } else if (log_.empty() && logged_keys_ == 0 && log_start_version_ == 0 && previous > 0) {
      log_start_version_ = previous;  // first publish after a loaded snapshot
    }
    if (!reset) {
      logged_keys_ += changed.size();
      log_.push_back({snapshot->version, std::move(changed)});
      while (logged_keys_ > max_logged_keys_ && !log_.empty()) {
        logged_keys_ -= log_.front().keys.size();
        log_start_version_ = log_.front().version;
        forgotten.push_back(std::move(log_.front()));
        log_.pop_front();
      }
    }
    // The version replaced now stays referenced until the next Publish, so that a query that
    // still reads it does not end up freeing it on a gRPC thread; the one before goes now.
    previous_snapshot = std::move(retired_);
    retired_ = std::move(current_);
    current_ = std::move(snapshot);
  }
  Notify();
}

bool SnapshotHub::ChangedSince(std::uint64_t since, std::vector<octomap::OcTreeKey>* keys) const {
  std::lock_guard<std::mutex> lock(mutex_);
  if (since < log_start_version_) return false;
  std::unordered_set<octomap::OcTreeKey, octomap::OcTreeKey::KeyHash> seen;
  for (const auto& entry : log_) {
    if (entry.version <= since) continue;
    for (const auto& key : entry.keys) {
      if (seen.insert(key).second) keys->push_back(key);
    }
  }
  return true;
}

int SnapshotHub::Subscribe(std::function<void()> callback) {
  std::lock_guard<std::mutex> lock(subscribers_mutex_);
  const int id = next_id_++;
  subscribers_.emplace(id, std::move(callback));
  return id;
}

void SnapshotHub::Unsubscribe(int id) {
  std::lock_guard<std::mutex> lock(subscribers_mutex_);
  subscribers_.erase(id);
}

void SnapshotHub::Close() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    closed_ = true;
  }
  Notify();
}

bool SnapshotHub::closed() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return closed_;
}

void SnapshotHub::Notify() {
  {
    std::lock_guard<std::mutex> lock(notify_mutex_);
    ++requested_;
  }
  notify_cv_.notify_all();
}

void SnapshotHub::Flush() {
  std::unique_lock<std::mutex> lock(notify_mutex_);
  const std::uint64_t target = requested_;
  notify_cv_.wait(lock, [&] { return delivered_ >= target || stop_notifier_; });
}

void SnapshotHub::NotifierLoop() {
  std::unique_lock<std::mutex> lock(notify_mutex_);
  while (true) {
    notify_cv_.wait(lock, [&] { return requested_ != delivered_ || stop_notifier_; });
    if (stop_notifier_) return;
    const std::uint64_t target = requested_;
    lock.unlock();
    {
      std::lock_guard<std::mutex> subscribers_lock(subscribers_mutex_);
      for (auto& entry : subscribers_) entry.second();
    }
    lock.lock();
    delivered_ = target;
    notify_cv_.notify_all();  // Flush
  }
}

}  // namespace fusion::service
