#include "fusion/service/persister.h"

#include <spdlog/spdlog.h>

#include "fusion/service/persistence.h"

namespace fusion::service {

Persister::Persister(std::string path, std::chrono::seconds interval, SnapshotHub* hub)
    : path_(std::move(path)), interval_(interval), hub_(hub) {}

Persister::~Persister() { Stop(); }

void Persister::Start() {
  if (enabled() && interval_.count() > 0) thread_ = std::thread([this] { Loop(); });
}

void Persister::Stop() {
  {
    std::lock_guard<std::mutex> lock(stop_mutex_);
    stop_ = true;
  }
  stop_cv_.notify_all();
  if (thread_.joinable()) thread_.join();
}

void Persister::set_saved_version(std::uint64_t version) {
  std::lock_guard<std::mutex> lock(write_mutex_);
  saved_version_ = version;
}

Status Persister::SaveNow(std::uint64_t* version, std::uint64_t* bytes) {
  if (!enabled()) return Status::Error("no persistence.path configured");
  std::lock_guard<std::mutex> lock(write_mutex_);
  const auto snapshot = hub_->Current();
  const auto start = std::chrono::steady_clock::now();
  if (Status written = WriteSnapshotFile(*snapshot->tree, path_, bytes); !written.ok()) {
    spdlog::error("snapshot: {}", written.message());
    failures_.fetch_add(1);
    {
      std::lock_guard<std::mutex> error_lock(error_mutex_);
      last_error_ = written.message();
    }
    if (!failing_.exchange(true) && on_health_) on_health_(false);
    return written;
  }
  if (failing_.exchange(false)) {
    spdlog::info("snapshot: writes succeed again");
    if (on_health_) on_health_(true);
  }
  saved_version_ = snapshot->version;
  *version = snapshot->version;
  saves_.fetch_add(1);
  spdlog::info(
      "snapshot: version {} written to {} ({} bytes, {:.1f} ms)", snapshot->version, path_, *bytes,
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count());
  return Status::Ok();
}

std::string Persister::last_error() const {
  std::lock_guard<std::mutex> lock(error_mutex_);
  return last_error_;
}

void Persister::Loop() {
  std::unique_lock<std::mutex> lock(stop_mutex_);
  while (!stop_cv_.wait_for(lock, interval_, [this] { return stop_; })) {
    lock.unlock();
    bool changed = false;
    {
      std::lock_guard<std::mutex> write_lock(write_mutex_);
      changed = hub_->Current()->version != saved_version_;
    }
    if (changed) {
      std::uint64_t version = 0, bytes = 0;
      (void)SaveNow(&version, &bytes);  // logs its own errors and counts them
    }
    lock.lock();
  }
}

}  // namespace fusion::service
