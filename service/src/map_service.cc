#include "fusion/service/map_service.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <mutex>
#include <set>

#include "fusion/core/forward_model.h"
#include "fusion/core/octree_merge.h"
#include "fusion/core/planes.h"
#include "fusion/service/persistence.h"
#include "handler_support.h"
#include "map_streams.h"

namespace fusion::service {
namespace {

using fusion::v1::VoxelState;
using grpc::Status;
using grpc::StatusCode;

constexpr double kMaxRayRangeM = 1000.0;
constexpr std::uint32_t kMaxPlanes = 64;
constexpr std::size_t kDeadlineCheckEvery = 4096;
// QueryBox boxes up to this many voxels (64^3) are answered on gRPC's threads.
constexpr double kCheapBoxVoxels = 262'144;

// Whether the node at `depth` whose iterator key is `key` (its centre) shares a voxel with the
// key box [kmin, kmax]. OctoMap's leaf_bbx_iterator also yields nodes that end one key before
// the box's minimum, so QueryBox checks every leaf it yields.
bool NodeOverlapsKeyBox(const octomap::OcTreeKey& key, unsigned depth,
                        const octomap::OcTreeKey& kmin, const octomap::OcTreeKey& kmax) {
  const unsigned half = depth >= 16 ? 0u : (32768u >> depth);
  for (int axis = 0; axis < 3; ++axis) {
    const unsigned lo = key[axis] - half;
    const unsigned hi = half == 0 ? key[axis] : key[axis] + half - 1;
    if (hi < kmin[axis] || lo > kmax[axis]) return false;
  }
  return true;
}

// Voxels of a QueryBox request's box at the given resolution (+inf for an invalid box: the
// handler then refuses it).
double BoxVoxels(const fusion::v1::QueryBoxRequest& request, double resolution_m) {
  double voxels = 1.0;
  const auto axis = [&](double lo, double hi) {
    const double n = std::floor(hi / resolution_m) - std::floor(lo / resolution_m) + 1.0;
    voxels *= std::isfinite(n) && n >= 1.0 ? n : std::numeric_limits<double>::infinity();
  };
  axis(request.min().x(), request.max().x());
  axis(request.min().y(), request.max().y());
  axis(request.min().z(), request.max().z());
  return voxels;
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
    reply->set_map_leaves(snapshot->sizes().leaves);
    reply->set_map_memory_bytes(snapshot->sizes().memory_bytes);
    reply->set_resolution_m(snapshot->tree->getResolution());
    reply->set_sensor_memory_bytes(memory);
    reply->set_snapshots_saved(state_->persister->saves());
    reply->set_snapshots_failed(state_->persister->failures());
    if (state_->persister->failing())
      reply->set_last_snapshot_error(state_->persister->last_error());
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
  auto body = [this, context, request, reply]() -> Status {
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
        if (!NodeOverlapsKeyBox(k, it.getDepth(), kmin, kmax)) continue;
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
  };
  // A small box is a cheap call (at most kCheapBoxVoxels lookups); a larger one is admitted as
  // an expensive call and runs on the heavy-query pool.
  return BoxVoxels(*request, state_->hub->Current()->tree->getResolution()) <= kCheapBoxVoxels
             ? Unary(context, state_, "QueryBox", body)
             : Heavy(context, state_, "QueryBox", body);
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
      info->set_cells_per_beam(
          CellsPerBeam(sensor.spec.r_max_m, state_->config.map().beam_cell_size_m()));
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
    return NewSnapshotWriter(state_, request->format(), std::move(*slot));
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
    return new ErrorWriter<fusion::v1::MapUpdate>(
        Status(StatusCode::RESOURCE_EXHAUSTED, "StreamUpdates: " + std::to_string(limit) +
                                                   " update streams are open already "
                                                   "(limits.max_update_streams)"));
  }
  try {
    return NewUpdateWriter(state_, request->since_version(), request->versions_only(),
                           std::move(*slot));
  } catch (const std::exception& e) {
    return new ErrorWriter<fusion::v1::MapUpdate>(
        Status(StatusCode::INTERNAL, std::string("StreamUpdates: ") + e.what()));
  }
}

}  // namespace fusion::service
