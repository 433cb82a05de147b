#include "fusion/service/map_snapshot.h"


namespace fusion::service {

SnapshotHub::SnapshotHub(std::size_t max_logged_regions, double resolution_m)
    : log_(max_logged_regions) {
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

void SnapshotHub::Publish(std::shared_ptr<const MapSnapshot> snapshot, MapChanges changes) {
  // The version replaced is let go of after the lock is released: should this be its last
  // reference, freeing an octree takes milliseconds, and every query takes this lock.
  std::shared_ptr<const MapSnapshot> previous;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    log_.Add(std::move(changes));
    previous = std::move(current_);
    current_ = std::move(snapshot);
  }
  Notify();
}

bool SnapshotHub::ChangedSince(std::uint64_t since, std::vector<MapRegion>* regions) const {
  std::lock_guard<std::mutex> lock(mutex_);
  return log_.Since(since, regions);
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
