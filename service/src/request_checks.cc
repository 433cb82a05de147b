#include "fusion/service/request_checks.h"

#include <cmath>
#include <cstdio>

#include "fusion/service/conversions.h"

namespace fusion::service {
namespace {

using grpc::Status;
using grpc::StatusCode;

Status Invalid(const std::string& message) { return Status(StatusCode::INVALID_ARGUMENT, message); }

// x in [lo, hi], or 0 (the default); NaN fails.
bool ZeroOrWithin(double x, double lo, double hi) { return x == 0.0 || (x >= lo && x <= hi); }

}  // namespace

bool FinitePoint(const fusion::v1::Point& p) {
  return std::isfinite(p.x()) && std::isfinite(p.y()) && std::isfinite(p.z());
}

Status CheckQueryPoints(const fusion::v1::QueryPointsRequest& request,
                        const fusion::v1::QueryLimits& limits) {
  const auto limit = limits.max_points_per_query();
  if (static_cast<std::uint64_t>(request.points_size()) > limit) {
    return Status(StatusCode::RESOURCE_EXHAUSTED,
                  std::to_string(request.points_size()) + " points; the limit is " +
                      std::to_string(limit) + " per call (limits.max_points_per_query)");
  }
  for (int i = 0; i < request.points_size(); ++i) {
    if (!FinitePoint(request.points(i))) {
      return Invalid("points[" + std::to_string(i) + "] has a NaN or infinite coordinate");
    }
  }
  return Status::OK;
}

Status CheckQueryBox(const fusion::v1::QueryBoxRequest& request,
                     const fusion::v1::QueryLimits& limits, BoxQuery* query) {
  if (!FinitePoint(request.min()) || !FinitePoint(request.max())) {
    return Invalid("min and max must be finite");
  }
  query->min_m = FromProto(request.min());
  query->max_m = FromProto(request.max());
  if ((query->min_m.array() > query->max_m.array()).any()) {
    return Invalid("min must not exceed max on any axis");
  }
  query->page_size =
      request.page_size() == 0 ? limits.max_voxels_per_page() : request.page_size();
  if (query->page_size > limits.max_voxels_per_page()) {
    return Status(StatusCode::RESOURCE_EXHAUSTED,
                  "page_size " + std::to_string(query->page_size) +
                      " exceeds limits.max_voxels_per_page " +
                      std::to_string(limits.max_voxels_per_page()));
  }
  query->states = std::set<int>(request.states().begin(), request.states().end());
  if (query->states.empty()) {
    query->states = {fusion::v1::VOXEL_STATE_OCCUPIED, fusion::v1::VOXEL_STATE_FREE};
  }
  for (int s : query->states) {
    if (!fusion::v1::VoxelState_IsValid(s)) {
      return Invalid("states: unknown value " + std::to_string(s));
    }
  }
  query->has_token = !request.page_token().empty();
  if (query->has_token && !DecodePageToken(request.page_token(), &query->after)) {
    return Invalid("page_token is malformed");
  }
  return Status::OK;
}

Status CheckCastRay(const fusion::v1::CastRayRequest& request) {
  if (!FinitePoint(request.origin()) || !FinitePoint(request.direction())) {
    return Invalid("origin and direction must be finite");
  }
  if (FromProto(request.direction()).norm() < 1e-9) return Invalid("direction must not be zero");
  if (!(request.max_range_m() > 0.0 && request.max_range_m() <= kMaxRayRangeM)) {
    return Invalid("max_range_m must lie in (0, 1000]");
  }
  return Status::OK;
}

Status CheckFindPlanes(const fusion::v1::FindPlanesRequest& request) {
  if (request.has_region_min() != request.has_region_max()) {
    return Invalid("give both region_min and region_max or none");
  }
  if (!FinitePoint(request.region_min()) || !FinitePoint(request.region_max()) ||
      (FromProto(request.region_min()).array() > FromProto(request.region_max()).array()).any()) {
    return Invalid("region must be finite with min <= max");
  }
  if (request.max_planes() > kMaxPlanes) {
    return Status(StatusCode::RESOURCE_EXHAUSTED, "max_planes is limited to 64");
  }
  if (!(request.min_probability() >= 0.0 && request.min_probability() < 1.0)) {
    return Invalid("min_probability must lie in [0, 1)");
  }
  if (!ZeroOrWithin(request.angle_step_deg(), 0.1, 45.0)) {
    return Invalid("angle_step_deg must lie in [0.1, 45]");
  }
  if (!ZeroOrWithin(request.distance_step_m(), 0.001, 10.0)) {
    return Invalid("distance_step_m must lie in [0.001, 10]");
  }
  return Status::OK;
}

Status CheckInspectBeam(const fusion::v1::InspectBeamRequest& request) {
  if (request.sensor_id().empty()) return Invalid("sensor_id must be given");
  return Status::OK;
}

Status CheckGetSnapshot(const fusion::v1::GetSnapshotRequest& request) {
  if (!fusion::v1::GetSnapshotRequest::Format_IsValid(request.format())) {
    return Invalid("format: unknown value");
  }
  return Status::OK;
}

Status CheckClearBox(const fusion::v1::ClearBoxRequest& request, Eigen::AlignedBox3d* box) {
  if (!request.has_min() || !request.has_max()) return Invalid("give both min and max");
  if (!FinitePoint(request.min()) || !FinitePoint(request.max())) {
    return Invalid("min and max must be finite");
  }
  *box = Eigen::AlignedBox3d(FromProto(request.min()), FromProto(request.max()));
  if ((box->min().array() > box->max().array()).any()) {
    return Invalid("min must not exceed max on any axis");
  }
  return Status::OK;
}

std::string EncodePageToken(const octomap::OcTreeKey& key) {
  return "k" + std::to_string(key[0]) + "." + std::to_string(key[1]) + "." + std::to_string(key[2]);
}

bool DecodePageToken(const std::string& token, octomap::OcTreeKey* key) {
  unsigned a = 0, b = 0, c = 0;
  char tail = 0;
  if (std::sscanf(token.c_str(), "k%u.%u.%u%c", &a, &b, &c, &tail) != 3) return false;
  if (a > 0xffff || b > 0xffff || c > 0xffff) return false;
  *key = octomap::OcTreeKey(a, b, c);
  return true;
}

}  // namespace fusion::service
