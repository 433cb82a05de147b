// The checks of the FusionMap requests that need no map: each gives OK or the status the
// handler answers with (INVALID_ARGUMENT for a malformed request, RESOURCE_EXHAUSTED for one
// over a documented limit, naming the field or the limit). The handlers (map_service.cc) run
// them first; what needs the map's key range is checked there.
#pragma once

#include <grpcpp/grpcpp.h>
#include <octomap/OcTreeKey.h>

#include <Eigen/Geometry>
#include <cstdint>
#include <set>
#include <string>

#include "fusion/v1/config.pb.h"
#include "fusion/v1/map_service.pb.h"

namespace fusion::service {

constexpr double kMaxRayRangeM = 1000.0;
constexpr std::uint32_t kMaxPlanes = 64;

[[nodiscard]] bool FinitePoint(const fusion::v1::Point& p);

[[nodiscard]] grpc::Status CheckQueryPoints(const fusion::v1::QueryPointsRequest& request,
                                            const fusion::v1::QueryLimits& limits);

// A QueryBox request as the handler uses it.
struct BoxQuery {
  Eigen::Vector3d min_m = Eigen::Vector3d::Zero(), max_m = Eigen::Vector3d::Zero();  // world
  std::uint32_t page_size = 0;  // voxels per page (the limit when the request says 0)
  std::set<int> states;         // VoxelState values asked for (occupied and free by default)
  bool has_token = false;       // page_token given: answer the keys after `after`
  octomap::OcTreeKey after{0, 0, 0};
};
[[nodiscard]] grpc::Status CheckQueryBox(const fusion::v1::QueryBoxRequest& request,
                                         const fusion::v1::QueryLimits& limits, BoxQuery* query);

[[nodiscard]] grpc::Status CheckCastRay(const fusion::v1::CastRayRequest& request);
[[nodiscard]] grpc::Status CheckFindPlanes(const fusion::v1::FindPlanesRequest& request);
[[nodiscard]] grpc::Status CheckInspectBeam(const fusion::v1::InspectBeamRequest& request);
[[nodiscard]] grpc::Status CheckGetSnapshot(const fusion::v1::GetSnapshotRequest& request);
// Finite corners, min <= max; *box (world frame) receives the box.
[[nodiscard]] grpc::Status CheckClearBox(const fusion::v1::ClearBoxRequest& request,
                                         Eigen::AlignedBox3d* box);

// QueryBox page tokens: the key after which the next page starts.
[[nodiscard]] std::string EncodePageToken(const octomap::OcTreeKey& key);
[[nodiscard]] bool DecodePageToken(const std::string& token, octomap::OcTreeKey* key);

}  // namespace fusion::service
