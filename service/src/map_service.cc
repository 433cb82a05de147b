#include "fusion/service/map_service.h"

#include <spdlog/spdlog.h>

#include "fusion/core/forward_model.h"
#include "fusion/core/octree_merge.h"
#include "fusion/core/planes.h"
#include "fusion/service/persistence.h"
#include "fusion/service/request_checks.h"
#include "handler_support.h"
#include "map_queries.h"
#include "map_streams.h"

namespace fusion::service {
namespace {

using grpc::Status;
using grpc::StatusCode;

constexpr std::size_t kDeadlineCheckEvery = 4096;
// QueryBox boxes up to this many voxels (64^3) are answered on gRPC's threads.
constexpr double kCheapBoxVoxels = 262'144;

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
    std::uint64_t received = 0, dropped = 0, memory = 0, changes = 0;
    for (const auto& id : state_->queues->SensorIds()) {
      const auto* c = state_->queues->counters(id);
      received += c->received;
      dropped += c->dropped;
      memory += c->memory_bytes;
      changes += c->changes_detected;
    }
    reply->set_changes_detected(changes);
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
    reply->set_matched_writers(state_->queues->matched_writers().current.load());
    reply->set_matched_writers_total(state_->queues->matched_writers().total.load());
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
    if (Status checked = CheckQueryPoints(*request, state_->config.limits()); !checked.ok()) {
      return checked;
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
    BoxQuery query;
    if (Status checked = CheckQueryBox(*request, limits, &query); !checked.ok()) return checked;
    const auto snapshot = state_->hub->Current();
    const octomap::OcTree& tree = *snapshot->tree;
    octomap::OcTreeKey kmin, kmax;
    if (!KeyOf(tree, query.min_m, &kmin) || !KeyOf(tree, query.max_m, &kmax)) {
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
    std::vector<BoxVoxel> page;
    if (!CollectBoxPage(tree, kmin, kmax, query, state_->thresholds,
                        [this, context] { return Stopped(context, state_); }, &page)) {
      return DeadlineExceeded("QueryBox");
    }
    const bool more = page.size() > query.page_size;
    if (more) page.resize(query.page_size);
    for (const BoxVoxel& v : page) {
      VoxelToProto(tree, v.key, v.depth, v.node, state_->thresholds, reply->add_voxels());
    }
    if (more) reply->set_next_page_token(EncodePageToken(page.back().key));
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
    if (Status checked = CheckCastRay(*request); !checked.ok()) return checked;
    const Eigen::Vector3d origin = FromProto(request->origin());
    const Eigen::Vector3d direction = FromProto(request->direction());
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
    if (Status checked = CheckFindPlanes(*request); !checked.ok()) return checked;
    const auto snapshot = state_->hub->Current();
    reply->set_map_version(snapshot->version);
    auto options = HoughOptionsFromProto(*request, snapshot->tree->getResolution());
    options.max_accumulator_cells = state_->config.limits().max_plane_cells();
    options.stop = [this, context] { return Stopped(context, state_); };
    // CheckFindPlanes keeps requests within core's bounds; this says which one if not.
    if (std::string why; !options.IsValid(&why)) {
      return Status(StatusCode::INVALID_ARGUMENT, "FindPlanes: " + why);
    }
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
      // A camera's beams may come with its first CameraInfo: the worker's spec has them.
      const SensorSpec spec =
          state_->worker ? state_->worker->SpecOf(sensor.id).value_or(sensor.spec) : sensor.spec;
      auto* info = reply->add_sensors();
      info->set_id(sensor.id);
      info->set_preset(sensor.preset);
      info->set_cols(spec.cols);
      info->set_rows(spec.rows);
      info->set_beams(spec.cols * spec.rows);
      info->set_cells_per_beam(CellsPerBeam(spec.r_max_m, state_->config.map().beam_cell_size_m()));
      info->set_memory_bytes(c->memory_bytes);
      auto* out = info->mutable_counters();
      out->set_received(c->received + c->rejected.Total());
      out->set_rejected(c->rejected.Total());
      out->set_dropped(c->dropped);
      out->set_integrated(c->integrated);
      out->set_merged(c->merged);
      out->set_changes_detected(c->changes_detected);
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
    if (Status checked = CheckInspectBeam(*request); !checked.ok()) return checked;
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

grpc::ServerUnaryReactor* MapService::ClearBox(grpc::CallbackServerContext* context,
                                               const fusion::v1::ClearBoxRequest* request,
                                               fusion::v1::ClearBoxResponse* reply) {
  return Unary(context, state_, "ClearBox", [&] {
    Eigen::AlignedBox3d box;
    if (Status checked = CheckClearBox(*request, &box); !checked.ok()) return checked;
    std::uint64_t voxels = 0;
    reply->set_map_version(state_->worker->ClearBox(box, &voxels));
    reply->set_voxels_cleared(voxels);
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
    if (const fusion::Status saved = state_->persister->SaveNow(&version, &bytes); !saved.ok()) {
      return Status(StatusCode::INTERNAL, "snapshot not written: " + saved.message());
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
    if (Status checked = CheckGetSnapshot(*request); !checked.ok()) {
      return new ErrorWriter<fusion::v1::SnapshotChunk>(checked);
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
