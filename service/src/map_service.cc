#include "fusion/service/map_service.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <mutex>
#include <set>

#include "fusion/core/octree_merge.h"
#include "fusion/core/planes.h"
#include "fusion/service/persistence.h"

namespace fusion::service {
namespace {

using fusion::v1::VoxelState;
using grpc::Status;
using grpc::StatusCode;

constexpr double kMaxRayRangeM = 1000.0;
constexpr std::uint32_t kMaxPlanes = 64;
constexpr std::size_t kDeadlineCheckEvery = 4096;

// Runs a handler body: no exception escapes, every outcome is a status.
template <typename Body>
Status RunBody(const ServiceState* state, const char* name, Body& body) {
  Status status;
  if (state->shutting_down) {
    status = Status(StatusCode::UNAVAILABLE, "fusiond is shutting down");
  } else {
    try {
      status = body();
    } catch (const std::bad_alloc&) {
      status = Status(StatusCode::RESOURCE_EXHAUSTED, std::string(name) + ": out of memory");
    } catch (const std::exception& e) {
      spdlog::error("{}: {}", name, e.what());
      status = Status(StatusCode::INTERNAL, std::string(name) + ": " + e.what());
    }
  }
  if (!status.ok()) spdlog::debug("{}: {} {}", name, status.error_code(), status.error_message());
  return status;
}

// A cheap call: answered on gRPC's thread, finished once.
template <typename Body>
grpc::ServerUnaryReactor* Unary(grpc::CallbackServerContext* context, const ServiceState* state,
                                const char* name, Body&& body) {
  auto* reactor = context->DefaultReactor();
  reactor->Finish(RunBody(state, name, body));
  return reactor;
}

Status AdmitHeavy(ServiceState* state, const char* name, std::optional<CountedSlot>* slot);

// An expensive call: admitted (AdmitHeavy), then run on the low-priority query pool. The body
// must capture by value what it uses (the request and reply live until Finish).
template <typename Body>
grpc::ServerUnaryReactor* Heavy(grpc::CallbackServerContext* context, ServiceState* state,
                                const char* name, Body body) {
  auto* reactor = context->DefaultReactor();
  std::optional<CountedSlot> slot;
  Status admitted = state->shutting_down
                        ? Status(StatusCode::UNAVAILABLE, "fusiond is shutting down")
                        : AdmitHeavy(state, name, &slot);
  if (!admitted.ok()) {
    reactor->Finish(admitted);
    return reactor;
  }
  auto held = std::make_shared<std::optional<CountedSlot>>(std::move(slot));
  state->heavy_pool->Post([reactor, state, name, body, held]() mutable {
    Status status = RunBody(state, name, body);
    held->reset();  // free before the client hears back: its next call finds the slot
    reactor->Finish(status);
  });
  return reactor;
}

bool Expired(const grpc::CallbackServerContext* context) {
  return context->IsCancelled() || context->deadline() < std::chrono::system_clock::now();
}

// Expired, or fusiond shutting down: what an expensive call's loops poll.
bool Stopped(const grpc::CallbackServerContext* context, const ServiceState* state) {
  return state->shutting_down || Expired(context);
}

// Admission of an expensive call (docs/service.md, "Overload"): OK with *slot held, or the
// status that sheds it.
Status AdmitHeavy(ServiceState* state, const char* name, std::optional<CountedSlot>* slot) {
  const auto& limits = state->config.limits();
  if (state->pressure.Behind(*state->queues, std::chrono::steady_clock::now())) {
    return Status(StatusCode::UNAVAILABLE,
                  std::string(name) + ": fusiond is dropping clouds; expensive queries are shed "
                                      "until ingest keeps up (retry in a second)");
  }
  *slot = CountedSlot::Take(&state->heavy_queries, limits.max_heavy_queries());
  if (!*slot) {
    return Status(StatusCode::RESOURCE_EXHAUSTED,
                  std::string(name) + ": " + std::to_string(limits.max_heavy_queries()) +
                      " expensive queries are running already (limits.max_heavy_queries)");
  }
  return Status::OK;
}

Status DeadlineExceeded(const char* what) {
  return Status(StatusCode::DEADLINE_EXCEEDED, std::string(what) + ": deadline passed");
}

bool FinitePoint(const fusion::v1::Point& p) {
  return std::isfinite(p.x()) && std::isfinite(p.y()) && std::isfinite(p.z());
}

// Key of a world point if it lies inside the octree's key range.
bool KeyOf(const octomap::OcTree& tree, const Eigen::Vector3d& p, octomap::OcTreeKey* key) {
  return tree.coordToKeyChecked(
      octomap::point3d(static_cast<float>(p.x()), static_cast<float>(p.y()),
                       static_cast<float>(p.z())),
      *key);
}

double ProbabilityOf(const octomap::OcTreeNode* node) {
  return node != nullptr ? node->getOccupancy() : 0.5;
}

VoxelState StateOfNode(const octomap::OcTreeNode* node, const StateThresholds& t) {
  return node != nullptr ? StateOf(node->getOccupancy(), t) : fusion::v1::VOXEL_STATE_UNKNOWN;
}

std::string EncodeToken(const octomap::OcTreeKey& key) {
  return "k" + std::to_string(key[0]) + "." + std::to_string(key[1]) + "." + std::to_string(key[2]);
}

bool DecodeToken(const std::string& token, octomap::OcTreeKey* key) {
  unsigned a = 0, b = 0, c = 0;
  char tail = 0;
  if (std::sscanf(token.c_str(), "k%u.%u.%u%c", &a, &b, &c, &tail) != 3) return false;
  if (a > 0xffff || b > 0xffff || c > 0xffff) return false;
  *key = octomap::OcTreeKey(a, b, c);
  return true;
}

bool KeyLess(const octomap::OcTreeKey& a, const octomap::OcTreeKey& b) {
  return std::make_tuple(a[0], a[1], a[2]) < std::make_tuple(b[0], b[1], b[2]);
}

// ---- streams --------------------------------------------------------------------------------

class SnapshotWriter final : public grpc::ServerWriteReactor<fusion::v1::SnapshotChunk> {
 public:
  // Serializes the current map on the query pool, then streams it in chunks. The slot (one of
  // limits.max_heavy_queries) is held until the stream ends: one copy of the map per slot.
  SnapshotWriter(ServiceState* state, fusion::v1::GetSnapshotRequest::Format format,
                 CountedSlot slot)
      : chunk_bytes_(state->config.limits().snapshot_chunk_bytes()), slot_(std::move(slot)) {
    state->heavy_pool->Post([this, state, format] {
      try {
        const auto snapshot = state->hub->Current();
        data_ = format == fusion::v1::GetSnapshotRequest::FORMAT_BT ? SerializeBt(*snapshot->tree)
                                                                    : SerializeOt(*snapshot->tree);
        version_ = snapshot->version;
      } catch (const std::exception& e) {
        Finish(Status(StatusCode::INTERNAL, std::string("GetSnapshot: ") + e.what()));
        return;
      }
      WriteNext();
    });
  }
  void OnWriteDone(bool ok) override {
    if (!ok) {
      Finish(Status(StatusCode::CANCELLED, "snapshot stream broken"));
      return;
    }
    WriteNext();
  }
  void OnDone() override { delete this; }

 private:
  void WriteNext() {
    if (offset_ >= data_.size()) {
      Finish(Status::OK);
      return;
    }
    const std::size_t n = std::min(chunk_bytes_, data_.size() - offset_);
    chunk_.set_map_version(version_);
    chunk_.set_total_bytes(data_.size());
    chunk_.set_offset(offset_);
    chunk_.set_data(data_.data() + offset_, n);
    offset_ += n;
    StartWrite(&chunk_);
  }

  std::size_t chunk_bytes_;
  CountedSlot slot_;
  std::string data_;
  std::uint64_t version_ = 0;
  std::size_t offset_ = 0;
  fusion::v1::SnapshotChunk chunk_;
};

class UpdateWriter final : public grpc::ServerWriteReactor<fusion::v1::MapUpdate> {
 public:
  // Pages of one incremental batch a subscriber may hold before it gets a full resend instead.
  static constexpr std::size_t kMaxBatchPages = 8;

  UpdateWriter(ServiceState* state, std::uint64_t since, bool versions_only, CountedSlot slot)
      : state_(state),
        slot_(std::move(slot)),
        sent_version_(since),
        full_next_(since == 0),
        versions_only_(versions_only) {
    // Subscribed before taking mutex_: the hub calls OnPublish with its subscriber lock held,
    // and OnPublish takes mutex_ (one lock order). A publish in between waits for started_.
    subscription_ = state_->hub->Subscribe([this] { OnPublish(); });
    std::lock_guard<std::mutex> lock(mutex_);
    PrepareLocked(/*first=*/true);
    started_ = true;
    WriteNextLocked();
  }
  void OnWriteDone(bool ok) override {
    std::lock_guard<std::mutex> lock(mutex_);
    writing_ = false;
    if (!ok) {
      FinishLocked(Status(StatusCode::CANCELLED, "update stream broken"));
      return;
    }
    WriteNextLocked();
  }
  void OnCancel() override {
    std::lock_guard<std::mutex> lock(mutex_);
    if (!writing_) FinishLocked(Status(StatusCode::CANCELLED, "cancelled"));
    cancelled_ = true;
  }
  void OnDone() override {
    state_->hub->Unsubscribe(subscription_);
    delete this;
  }

 private:
  void OnPublish() {
    std::lock_guard<std::mutex> lock(mutex_);
    if (finished_ || cancelled_) return;
    if (started_ && pending_.empty() && !writing_ && !full_it_) {
      PrepareLocked(false);
      WriteNextLocked();
    } else {
      more_ = true;  // picked up when the queued messages are written
    }
  }

  // Builds the messages that bring the client from sent_version_ to the current version.
  void PrepareLocked(bool first) {
    const auto snapshot = state_->hub->Current();
    if (!first && snapshot->version <= sent_version_) return;
    if (versions_only_) {
      pending_.emplace_back();
      pending_.back().set_map_version(snapshot->version);
      pending_.back().set_from_version(sent_version_);
      pending_.back().set_complete(true);
      sent_version_ = snapshot->version;
      return;
    }
    const octomap::OcTree& tree = *snapshot->tree;
    const std::size_t per_message = state_->config.limits().max_voxels_per_page();
    std::vector<MapRegion> regions;
    const bool full = full_next_ || !state_->hub->ChangedSince(sent_version_, &regions);
    const auto new_message = [&] {
      pending_.emplace_back();
      pending_.back().set_map_version(snapshot->version);
      pending_.back().set_from_version(full ? 0 : sent_version_);
      pending_.back().set_full(full);
    };
    if (full) {
      // The whole map, one page at a time as the client takes them (NextFullPageLocked): a
      // subscriber holds one page and the version it reads, never the map as messages.
      full_snapshot_ = snapshot;
      full_it_ = tree.begin_leafs();
      sent_version_ = snapshot->version;
      full_next_ = false;
      NextFullPageLocked();
      return;
    }
    new_message();
    // What each changed region holds now: its leaves, or the region itself (one value, or
    // unknown where the map holds nothing any more). A change larger than kMaxBatchPages pages
    // is sent as a full resend instead, page by page, so that no subscriber buffers much.
    bool too_large = false;
    for (const MapRegion& region : regions) {
      ForEachInRegion(tree, region,
                      [&](const octomap::OcTreeKey& key, unsigned depth,
                          const octomap::OcTreeNode* node) {
                        if (too_large) return;
                        if (pending_.back().voxels_size() >= static_cast<int>(per_message)) {
                          if (pending_.size() >= kMaxBatchPages) {
                            too_large = true;
                            return;
                          }
                          new_message();
                        }
                        VoxelToProto(tree, key, depth, node, state_->thresholds,
                                     pending_.back().add_voxels());
                      });
      if (too_large) break;
    }
    if (too_large) {
      pending_.clear();
      full_next_ = true;
      PrepareLocked(/*first=*/true);
      return;
    }
    pending_.back().set_complete(true);
    sent_version_ = snapshot->version;
    full_next_ = false;
  }

  // The next page of a full resend, the last one `complete`.
  void NextFullPageLocked() {
    const octomap::OcTree& tree = *full_snapshot_->tree;
    const int per_message = static_cast<int>(state_->config.limits().max_voxels_per_page());
    pending_.emplace_back();
    fusion::v1::MapUpdate& page = pending_.back();
    page.set_map_version(full_snapshot_->version);
    page.set_from_version(0);
    page.set_full(true);
    for (auto& it = *full_it_; it != tree.end_leafs() && page.voxels_size() < per_message; ++it) {
      VoxelToProto(tree, it.getKey(), it.getDepth(), &*it, state_->thresholds, page.add_voxels());
    }
    if (*full_it_ == tree.end_leafs()) {
      page.set_complete(true);
      full_it_.reset();
      full_snapshot_.reset();
    }
  }

  void WriteNextLocked() {
    if (finished_) return;
    if (cancelled_) {
      FinishLocked(Status(StatusCode::CANCELLED, "cancelled"));
      return;
    }
    if (pending_.empty() && full_it_) NextFullPageLocked();
    if (pending_.empty() && (state_->hub->closed() || state_->shutting_down)) {
      FinishLocked(Status::OK);
      return;
    }
    if (pending_.empty() && more_ && !full_it_) {
      more_ = false;
      PrepareLocked(false);
    }
    if (pending_.empty()) return;
    current_ = std::move(pending_.front());
    pending_.pop_front();
    writing_ = true;
    StartWrite(&current_);
  }

  void FinishLocked(const Status& status) {
    if (finished_) return;
    finished_ = true;
    Finish(status);
  }

  ServiceState* state_;
  CountedSlot slot_;  // one of limits.max_update_streams
  std::mutex mutex_;
  int subscription_ = 0;
  std::uint64_t sent_version_;
  bool full_next_;
  bool versions_only_;
  std::deque<fusion::v1::MapUpdate> pending_;
  fusion::v1::MapUpdate current_;
  // A full resend in progress: the version it reads and where it stands.
  std::shared_ptr<const MapSnapshot> full_snapshot_;
  std::optional<octomap::OcTree::leaf_iterator> full_it_;
  bool started_ = false;  // the first messages are prepared
  bool writing_ = false;
  bool more_ = false;
  bool cancelled_ = false;
  bool finished_ = false;
};

template <typename Message>
class ErrorWriter final : public grpc::ServerWriteReactor<Message> {
 public:
  explicit ErrorWriter(const Status& status) { this->Finish(status); }
  void OnDone() override { delete this; }
};

}  // namespace

// ---- unary handlers --------------------------------------------------------------------------

grpc::ServerUnaryReactor* MapService::GetStats(grpc::CallbackServerContext* context,
                                               const fusion::v1::GetStatsRequest*,
                                               fusion::v1::Stats* reply) {
  return Unary(context, state_, "GetStats", [&] {
    const auto snapshot = state_->hub->Current();
    reply->set_map_version(snapshot->version);
    reply->set_uptime_s(
        std::chrono::duration<double>(std::chrono::steady_clock::now() - state_->start).count());
    std::uint64_t received = 0, dropped = 0, memory = 0;
    for (const auto& id : state_->queues->SensorIds()) {
      const auto* c = state_->queues->counters(id);
      received += c->received;
      dropped += c->dropped;
      memory += c->memory_bytes;
    }
    const auto& rejected = state_->queues->all_rejected();
    reply->set_clouds_received(received + rejected.Total());
    reply->set_clouds_rejected(rejected.Total());
    reply->set_clouds_dropped(dropped);
    reply->set_clouds_integrated(state_->worker->integrated());
    reply->set_renders(state_->worker->renders());
    reply->set_clouds_in_map(state_->worker->in_map());
    reply->set_map_leaves(snapshot->tree->getNumLeafNodes());
    reply->set_map_memory_bytes(snapshot->tree->memoryUsage());
    reply->set_resolution_m(snapshot->tree->getResolution());
    reply->set_sensor_memory_bytes(memory);
    reply->set_snapshots_saved(state_->persister->saves());
    reply->set_snapshots_failed(state_->persister->failures());
    if (state_->persister->failing()) reply->set_last_snapshot_error(state_->persister->last_error());
    reply->set_last_snapshot_path(state_->persister->path());
    for (std::size_t i = 0; i < kRejectReasonCount; ++i) {
      const auto n = rejected.by_reason[i].load();
      if (n > 0) (*reply->mutable_rejected_by_reason())[RejectReasonName(RejectReason(i))] = n;
    }
    return Status::OK;
  });
}

grpc::ServerUnaryReactor* MapService::QueryPoints(grpc::CallbackServerContext* context,
                                                  const fusion::v1::QueryPointsRequest* request,
                                                  fusion::v1::QueryPointsResponse* reply) {
  return Unary(context, state_, "QueryPoints", [&] {
    const auto limit = state_->config.limits().max_points_per_query();
    if (static_cast<std::uint64_t>(request->points_size()) > limit) {
      return Status(StatusCode::RESOURCE_EXHAUSTED,
                    std::to_string(request->points_size()) + " points; the limit is " +
                        std::to_string(limit) + " per call (limits.max_points_per_query)");
    }
    for (int i = 0; i < request->points_size(); ++i) {
      if (!FinitePoint(request->points(i))) {
        return Status(StatusCode::INVALID_ARGUMENT,
                      "points[" + std::to_string(i) + "] has a NaN or infinite coordinate");
      }
    }
    const auto snapshot = state_->hub->Current();
    const octomap::OcTree& tree = *snapshot->tree;
    reply->set_map_version(snapshot->version);
    reply->mutable_results()->Reserve(request->points_size());
    for (int i = 0; i < request->points_size(); ++i) {
      if (i % kDeadlineCheckEvery == 0 && Expired(context)) return DeadlineExceeded("QueryPoints");
      octomap::OcTreeKey key;
      const octomap::OcTreeNode* node =
          KeyOf(tree, FromProto(request->points(i)), &key) ? tree.search(key) : nullptr;
      auto* result = reply->add_results();
      result->set_probability(ProbabilityOf(node));
      result->set_state(StateOfNode(node, state_->thresholds));
    }
    return Status::OK;
  });
}

grpc::ServerUnaryReactor* MapService::QueryBox(grpc::CallbackServerContext* context,
                                               const fusion::v1::QueryBoxRequest* request,
                                               fusion::v1::QueryBoxResponse* reply) {
  return Heavy(context, state_, "QueryBox", [this, context, request, reply]() -> Status {
    const auto& limits = state_->config.limits();
    if (!FinitePoint(request->min()) || !FinitePoint(request->max())) {
      return Status(StatusCode::INVALID_ARGUMENT, "min and max must be finite");
    }
    const Eigen::Vector3d lo = FromProto(request->min()), hi = FromProto(request->max());
    if ((lo.array() > hi.array()).any()) {
      return Status(StatusCode::INVALID_ARGUMENT, "min must not exceed max on any axis");
    }
    const std::uint32_t page =
        request->page_size() == 0 ? limits.max_voxels_per_page() : request->page_size();
    if (page > limits.max_voxels_per_page()) {
      return Status(StatusCode::RESOURCE_EXHAUSTED,
                    "page_size " + std::to_string(page) + " exceeds limits.max_voxels_per_page " +
                        std::to_string(limits.max_voxels_per_page()));
    }
    std::set<int> states(request->states().begin(), request->states().end());
    if (states.empty()) states = {fusion::v1::VOXEL_STATE_OCCUPIED, fusion::v1::VOXEL_STATE_FREE};
    for (int s : states) {
      if (!fusion::v1::VoxelState_IsValid(s)) {
        return Status(StatusCode::INVALID_ARGUMENT, "states: unknown value " + std::to_string(s));
      }
    }
    octomap::OcTreeKey after(0, 0, 0);
    const bool has_token = !request->page_token().empty();
    if (has_token && !DecodeToken(request->page_token(), &after)) {
      return Status(StatusCode::INVALID_ARGUMENT, "page_token is malformed");
    }
    const auto snapshot = state_->hub->Current();
    const octomap::OcTree& tree = *snapshot->tree;
    octomap::OcTreeKey kmin, kmax;
    if (!KeyOf(tree, lo, &kmin) || !KeyOf(tree, hi, &kmax)) {
      return Status(StatusCode::INVALID_ARGUMENT, "the box reaches outside the map's key range");
    }
    const double voxels = double(kmax[0] - kmin[0] + 1) * double(kmax[1] - kmin[1] + 1) *
                          double(kmax[2] - kmin[2] + 1);
    if (voxels > double(limits.max_box_voxels())) {
      return Status(StatusCode::RESOURCE_EXHAUSTED,
                    "the box spans " + std::to_string(static_cast<std::uint64_t>(voxels)) +
                        " voxels; limits.max_box_voxels is " +
                        std::to_string(limits.max_box_voxels()));
    }
    reply->set_map_version(snapshot->version);
    struct Found {
      octomap::OcTreeKey key;
      unsigned depth;
      const octomap::OcTreeNode* node;
    };
    const auto less = [](const Found& a, const Found& b) { return KeyLess(a.key, b.key); };
    std::vector<Found> found;
    found.reserve(std::min<std::size_t>(page + 1, 1 << 16));
    std::size_t visited = 0;
    if (states.count(fusion::v1::VOXEL_STATE_UNKNOWN) != 0) {
      // Unknown voxels have no node: walk every key of the box in order, after the token.
      octomap::OcTreeKey k = kmin;
      for (unsigned x = kmin[0]; x <= kmax[0] && found.size() <= page; ++x) {
        for (unsigned y = kmin[1]; y <= kmax[1] && found.size() <= page; ++y) {
          for (unsigned z = kmin[2]; z <= kmax[2] && found.size() <= page; ++z) {
            k = octomap::OcTreeKey(x, y, z);
            if (++visited % kDeadlineCheckEvery == 0 && Stopped(context, state_)) {
              return DeadlineExceeded("QueryBox");
            }
            if (has_token && !KeyLess(after, k)) continue;
            const octomap::OcTreeNode* node = tree.search(k);
            if (states.count(StateOfNode(node, state_->thresholds)) != 0) {
              found.push_back({k, tree.getTreeDepth(), node});
            }
          }
        }
      }
    } else {
      for (auto it = tree.begin_leafs_bbx(kmin, kmax), end = tree.end_leafs_bbx(); it != end;
           ++it) {
        if (++visited % kDeadlineCheckEvery == 0 && Stopped(context, state_)) {
          return DeadlineExceeded("QueryBox");
        }
        const octomap::OcTreeKey k = it.getKey();
        if (has_token && !KeyLess(after, k)) continue;
        if (states.count(StateOfNode(&*it, state_->thresholds)) == 0) continue;
        // The page + 1 smallest keys, in a max-heap: memory is one page whatever the box holds.
        if (found.size() == page + 1 && !KeyLess(k, found.front().key)) continue;
        found.push_back({k, it.getDepth(), &*it});
        std::push_heap(found.begin(), found.end(), less);
        if (found.size() > page + 1) {
          std::pop_heap(found.begin(), found.end(), less);
          found.pop_back();
        }
      }
      std::sort_heap(found.begin(), found.end(), less);
    }
    const bool more = found.size() > page;
    if (more) found.resize(page);
    for (const Found& f : found) {
      VoxelToProto(tree, f.key, f.depth, f.node, state_->thresholds, reply->add_voxels());
    }
    if (more) reply->set_next_page_token(EncodeToken(found.back().key));
    return Status::OK;
  });
}

grpc::ServerUnaryReactor* MapService::CastRay(grpc::CallbackServerContext* context,
                                              const fusion::v1::CastRayRequest* request,
                                              fusion::v1::CastRayResponse* reply) {
  return Unary(context, state_, "CastRay", [&]() -> Status {
    if (!FinitePoint(request->origin()) || !FinitePoint(request->direction())) {
      return Status(StatusCode::INVALID_ARGUMENT, "origin and direction must be finite");
    }
    const Eigen::Vector3d origin = FromProto(request->origin());
    const Eigen::Vector3d direction = FromProto(request->direction());
    if (direction.norm() < 1e-9) {
      return Status(StatusCode::INVALID_ARGUMENT, "direction must not be zero");
    }
    if (!(request->max_range_m() > 0.0 && request->max_range_m() <= kMaxRayRangeM)) {
      return Status(StatusCode::INVALID_ARGUMENT, "max_range_m must lie in (0, 1000]");
    }
    const auto snapshot = state_->hub->Current();
    const octomap::OcTree& tree = *snapshot->tree;
    octomap::OcTreeKey key;
    if (!KeyOf(tree, origin, &key) ||
        !KeyOf(tree, origin + direction.normalized() * request->max_range_m(), &key)) {
      return Status(StatusCode::INVALID_ARGUMENT, "the ray leaves the map's key range");
    }
    reply->set_map_version(snapshot->version);
    const octomap::point3d o(origin.x(), origin.y(), origin.z());
    const octomap::point3d d(direction.x(), direction.y(), direction.z());
    octomap::point3d end;
    const bool hit = tree.castRay(o, d, end, request->ignore_unknown(), request->max_range_m());
    reply->set_hit(hit);
    ToProto(Eigen::Vector3d(end.x(), end.y(), end.z()), reply->mutable_end());
    reply->set_range_m((end - o).norm());
    reply->set_stopped_at(StateOfNode(tree.search(end), state_->thresholds));
    return Status::OK;
  });
}

grpc::ServerUnaryReactor* MapService::FindPlanes(grpc::CallbackServerContext* context,
                                                 const fusion::v1::FindPlanesRequest* request,
                                                 fusion::v1::FindPlanesResponse* reply) {
  return Heavy(context, state_, "FindPlanes", [this, context, request, reply]() -> Status {
    if (request->has_region_min() != request->has_region_max()) {
      return Status(StatusCode::INVALID_ARGUMENT, "give both region_min and region_max or none");
    }
    if (!FinitePoint(request->region_min()) || !FinitePoint(request->region_max()) ||
        (FromProto(request->region_min()).array() > FromProto(request->region_max()).array())
            .any()) {
      return Status(StatusCode::INVALID_ARGUMENT, "region must be finite with min <= max");
    }
    if (request->max_planes() > kMaxPlanes) {
      return Status(StatusCode::RESOURCE_EXHAUSTED, "max_planes is limited to 64");
    }
    if (!(request->min_probability() >= 0.0 && request->min_probability() < 1.0)) {
      return Status(StatusCode::INVALID_ARGUMENT, "min_probability must lie in [0, 1)");
    }
    if (!(request->angle_step_deg() >= 0.0 && request->angle_step_deg() <= 45.0) ||
        (request->angle_step_deg() > 0.0 && request->angle_step_deg() < 0.1)) {
      return Status(StatusCode::INVALID_ARGUMENT, "angle_step_deg must lie in [0.1, 45]");
    }
    if (!(request->distance_step_m() >= 0.0 && request->distance_step_m() <= 10.0) ||
        (request->distance_step_m() > 0.0 && request->distance_step_m() < 0.001)) {
      return Status(StatusCode::INVALID_ARGUMENT, "distance_step_m must lie in [0.001, 10]");
    }
    const auto snapshot = state_->hub->Current();
    reply->set_map_version(snapshot->version);
    auto options = HoughOptionsFromProto(*request, snapshot->tree->getResolution());
    options.max_accumulator_cells = state_->config.limits().max_plane_cells();
    options.stop = [this, context] { return Stopped(context, state_); };
    const PlaneSearch search = SearchPlanes(*snapshot->tree, options);
    if (search.status == PlaneSearchStatus::kTooLarge) {
      return Status(StatusCode::RESOURCE_EXHAUSTED,
                    "FindPlanes: the search needs " + std::to_string(search.accumulator_cells) +
                        " accumulator cells for " + std::to_string(search.voters) +
                        " voting voxels; limits.max_plane_cells is " +
                        std::to_string(options.max_accumulator_cells) +
                        " (coarser angle_step_deg / distance_step_m, or a region, need fewer)");
    }
    if (search.status == PlaneSearchStatus::kStopped) {
      if (state_->shutting_down) return Status(StatusCode::UNAVAILABLE, "fusiond is shutting down");
      return DeadlineExceeded("FindPlanes");
    }
    for (const Plane& plane : search.planes) PlaneToProto(plane, reply->add_planes());
    return Status::OK;
  });
}

grpc::ServerUnaryReactor* MapService::ListSensors(grpc::CallbackServerContext* context,
                                                  const fusion::v1::ListSensorsRequest*,
                                                  fusion::v1::ListSensorsResponse* reply) {
  return Unary(context, state_, "ListSensors", [&] {
    for (const auto& sensor : state_->sensors) {
      const auto* c = state_->queues->counters(sensor.id);
      auto* info = reply->add_sensors();
      info->set_id(sensor.id);
      info->set_preset(sensor.preset);
      info->set_cols(sensor.spec.cols);
      info->set_rows(sensor.spec.rows);
      info->set_beams(sensor.spec.cols * sensor.spec.rows);
      info->set_cells_per_beam(static_cast<std::uint64_t>(
          std::ceil(sensor.spec.r_max_m / state_->config.map().beam_cell_size_m())));
      info->set_memory_bytes(c->memory_bytes);
      auto* out = info->mutable_counters();
      out->set_received(c->received + c->rejected.Total());
      out->set_rejected(c->rejected.Total());
      out->set_dropped(c->dropped);
      out->set_integrated(c->integrated);
      out->set_merged(c->merged);
      out->set_points_updated(c->points_updated);
      out->set_points_beyond_range(c->points_beyond_range);
      out->set_points_missing(c->points_missing);
      out->set_points_rejected(c->points_rejected);
      out->set_last_sequence_number(c->last_sequence_number);
      for (std::size_t i = 0; i < kRejectReasonCount; ++i) {
        const auto n = c->rejected.by_reason[i].load();
        if (n > 0) (*out->mutable_rejected_by_reason())[RejectReasonName(RejectReason(i))] = n;
      }
    }
    return Status::OK;
  });
}

grpc::ServerUnaryReactor* MapService::InspectBeam(grpc::CallbackServerContext* context,
                                                  const fusion::v1::InspectBeamRequest* request,
                                                  fusion::v1::InspectBeamResponse* reply) {
  return Unary(context, state_, "InspectBeam", [&] {
    if (request->sensor_id().empty()) {
      return Status(StatusCode::INVALID_ARGUMENT, "sensor_id must be given");
    }
    BeamInspection beam;
    const auto lookup = state_->worker->InspectBeam(
        request->sensor_id(),
        request->has_beam() ? std::optional<std::size_t>(request->beam()) : std::nullopt,
        request->row(), request->col(), &beam);
    if (lookup == BeamLookup::kUnknownSensor) {
      return Status(StatusCode::NOT_FOUND, "no sensor '" + request->sensor_id() + "'");
    }
    if (lookup == BeamLookup::kBeamOutOfRange) {
      return Status(StatusCode::NOT_FOUND, "sensor '" + request->sensor_id() +
                                               "' has no such beam (index, row or col too large)");
    }
    reply->set_beam(static_cast<std::uint32_t>(beam.beam));
    reply->set_cell_size_m(beam.cell_size_m);
    ToProto(beam.direction_sensor, reply->mutable_direction());
    reply->mutable_first_hit()->Add(beam.first_hit.begin(), beam.first_hit.end());
    reply->mutable_cell_occupancy()->Add(beam.cell_occupancy.begin(), beam.cell_occupancy.end());
    reply->set_touched(beam.touched);
    return Status::OK;
  });
}

grpc::ServerUnaryReactor* MapService::ResetMap(grpc::CallbackServerContext* context,
                                               const fusion::v1::ResetMapRequest*,
                                               fusion::v1::ResetMapResponse* reply) {
  return Unary(context, state_, "ResetMap", [&] {
    reply->set_map_version(state_->worker->Reset());
    return Status::OK;
  });
}

grpc::ServerUnaryReactor* MapService::SaveMap(grpc::CallbackServerContext* context,
                                              const fusion::v1::SaveMapRequest*,
                                              fusion::v1::SaveMapResponse* reply) {
  return Unary(context, state_, "SaveMap", [&] {
    if (!state_->persister->enabled()) {
      return Status(StatusCode::FAILED_PRECONDITION,
                    "no persistence.path configured (set it or pass --snapshot)");
    }
    std::uint64_t version = 0, bytes = 0;
    std::string error;
    if (!state_->persister->SaveNow(&version, &bytes, &error)) {
      return Status(StatusCode::INTERNAL, "snapshot not written: " + error);
    }
    reply->set_path(state_->persister->path());
    reply->set_bytes(bytes);
    reply->set_map_version(version);
    return Status::OK;
  });
}

// ---- streaming handlers -----------------------------------------------------------------------

grpc::ServerWriteReactor<fusion::v1::SnapshotChunk>* MapService::GetSnapshot(
    grpc::CallbackServerContext*, const fusion::v1::GetSnapshotRequest* request) {
  if (state_->shutting_down) {
    return new ErrorWriter<fusion::v1::SnapshotChunk>(
        Status(StatusCode::UNAVAILABLE, "fusiond is shutting down"));
  }
  try {
    if (!fusion::v1::GetSnapshotRequest::Format_IsValid(request->format())) {
      return new ErrorWriter<fusion::v1::SnapshotChunk>(
          Status(StatusCode::INVALID_ARGUMENT, "format: unknown value"));
    }
    std::optional<CountedSlot> slot;
    if (Status admitted = AdmitHeavy(state_, "GetSnapshot", &slot); !admitted.ok()) {
      return new ErrorWriter<fusion::v1::SnapshotChunk>(admitted);
    }
    return new SnapshotWriter(state_, request->format(), std::move(*slot));
  } catch (const std::exception& e) {
    return new ErrorWriter<fusion::v1::SnapshotChunk>(
        Status(StatusCode::INTERNAL, std::string("GetSnapshot: ") + e.what()));
  }
}

grpc::ServerWriteReactor<fusion::v1::MapUpdate>* MapService::StreamUpdates(
    grpc::CallbackServerContext*, const fusion::v1::StreamUpdatesRequest* request) {
  if (state_->shutting_down) {
    return new ErrorWriter<fusion::v1::MapUpdate>(
        Status(StatusCode::UNAVAILABLE, "fusiond is shutting down"));
  }
  const std::uint32_t limit = state_->config.limits().max_update_streams();
  std::optional<CountedSlot> slot = CountedSlot::Take(&state_->update_streams, limit);
  if (!slot) {
    return new ErrorWriter<fusion::v1::MapUpdate>(Status(
        StatusCode::RESOURCE_EXHAUSTED,
        "StreamUpdates: " + std::to_string(limit) + " update streams are open already "
        "(limits.max_update_streams)"));
  }
  try {
    return new UpdateWriter(state_, request->since_version(), request->versions_only(),
                            std::move(*slot));
  } catch (const std::exception& e) {
    return new ErrorWriter<fusion::v1::MapUpdate>(
        Status(StatusCode::INTERNAL, std::string("StreamUpdates: ") + e.what()));
  }
}

}  // namespace fusion::service
