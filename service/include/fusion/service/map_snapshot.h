// Immutable map versions published by the fusion worker and read by the gRPC handlers: a
// handler takes the current pointer under a short lock and reads it while the worker goes on.
#pragma once

#include <octomap/OcTree.h>

#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <thread>
#include <vector>

#include "fusion/core/change_log.h"
#include "fusion/core/octree_merge.h"

namespace fusion::service {

struct MapSnapshot {
  std::uint64_t version = 0;
  std::shared_ptr<const octomap::OcTree> tree;  // never null
  // tree->getNumLeafNodes(), as the publisher keeps it (Publication::leaves): no walk here.
  std::size_t leaves = 0;

  struct Sizes {
    std::size_t leaves = 0;
    std::size_t memory_bytes = 0;
  };
  // The tree's leaf count and memory (OcTree::memoryUsage's figure) without a walk of the tree:
  // GetStats and the metrics stay cheap however often they are called (a client that read
  // GetStats at every version, as service_bench's sampler does, paid 6-11 % of fusiond's samples
  // for the walks; BENCHMARKS.md).
  [[nodiscard]] Sizes sizes() const { return {leaves, TreeMemoryBytes(*tree, leaves)}; }
};

class SnapshotHub {
 public:
  // Bound of the change log: older versions are forgotten (subscribers then get the full map).
  static constexpr std::size_t kDefaultMaxLoggedRegions = 4'000'000;
  // Until the first Publish, Current() is an empty map of resolution_m.
  explicit SnapshotHub(std::size_t max_logged_regions = kDefaultMaxLoggedRegions,
                       double resolution_m = 0.05);
  ~SnapshotHub();
  SnapshotHub(const SnapshotHub&) = delete;
  SnapshotHub& operator=(const SnapshotHub&) = delete;

  [[nodiscard]] std::shared_ptr<const MapSnapshot> Current() const;
  // Publishes a new version with what it changed (changes.version == snapshot->version;
  // changes.reset: the previous versions are gone).
  void Publish(std::shared_ptr<const MapSnapshot> snapshot, MapChanges changes);
  // Regions changed after `since` up to the current version (ChangeLog::Since). False if the
  // log does not reach back to `since` (the caller then sends the whole map).
  bool ChangedSince(std::uint64_t since, std::vector<MapRegion>* regions) const;

  // Subscribers are called on the hub's own notifier thread, so that the publisher (the fusion
  // worker) never waits for them: at least once after every Publish (several publishes in
  // quick succession may be reported by one call) and after Close. They must not call
  // Unsubscribe; after Unsubscribe returns, the callback is not called again.
  int Subscribe(std::function<void()> callback);
  void Unsubscribe(int id);
  // No more versions will come (shutdown).
  void Close();
  [[nodiscard]] bool closed() const;
  // Waits until the subscribers have been called for everything published or closed so far.
  void Flush();

 private:
  void Notify();
  void NotifierLoop();

  mutable std::mutex mutex_;
  std::shared_ptr<const MapSnapshot> current_;
  ChangeLog log_;
  bool closed_ = false;

  std::mutex subscribers_mutex_;  // held while calling subscribers
  std::map<int, std::function<void()>> subscribers_;
  int next_id_ = 1;

  std::mutex notify_mutex_;
  std::condition_variable notify_cv_;
  std::uint64_t requested_ = 0;  // notifications asked for
  std::uint64_t delivered_ = 0;  // of those, delivered to the subscribers
  bool stop_notifier_ = false;
  std::thread notifier_;
};

}  // namespace fusion::service
