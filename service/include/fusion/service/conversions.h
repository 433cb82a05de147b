// The one seam between wire types (protobuf config and API, DDS samples) and core types.
// Free functions only; nothing else lives here.
#pragma once

#include <octomap/OcTree.h>

#include <Eigen/Geometry>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "fusion/core/beam_grid.h"
#include "fusion/core/planes.h"
#include "fusion/core/sensor.h"
#include "fusion/core/status.h"
#include "fusion/core/world_map.h"
#include "fusion/service/cloud.h"
#include "fusion/v1/config.pb.h"
#include "fusion/v1/map_service.pb.h"
#include "fusion_dds.h"

namespace fusion::service {

// A configured sensor in core terms.
struct SensorSetup {
  std::string id;
  std::string preset;
  SensorSpec spec;
  // T_published_sensor: applied on the right of every sample's pose.
  Eigen::Isometry3d T_published_sensor = Eigen::Isometry3d::Identity();
  // Clouds that arrive while a render runs (~0.3 s for an SR-3000 at 2 cm) wait here: at
  // 30 Hz that is ~10; a queue of 2 dropped a third of them (BENCHMARKS.md).
  std::size_t queue_depth = 16;
};

// Thresholds that turn an occupancy probability into a state.
// Default: core's one threshold, no dead band (fusiond deploys one: config.cc, DefaultConfig).
struct StateThresholds {
  double occupied = WorldMapOptions::kDefaultOccupancyThreshold;  // p >= occupied: occupied
  double free = WorldMapOptions::kDefaultOccupancyThreshold;      // p < free: free (else unknown)
};

// Config -> core. An error names the field (relative to the message).
[[nodiscard]] StatusOr<SensorSetup> SensorSetupFromConfig(const fusion::v1::SensorConfig& c);
[[nodiscard]] StatusOr<WorldMapOptions> WorldMapOptionsFromConfig(const fusion::v1::MapConfig& c);
[[nodiscard]] StateThresholds ThresholdsFromConfig(const fusion::v1::MapConfig& c);
// A transform whose quaternion is all zero is the identity.
[[nodiscard]] Eigen::Isometry3d IsometryFromConfig(const fusion::v1::Transform& t);

// DDS -> core. The sample must have passed ValidateSample.
[[nodiscard]] Eigen::Isometry3d IsometryFromDds(const fusion_dds_Pose& pose);
[[nodiscard]] Cloud CloudFromDds(const fusion_dds_PointCloud& sample);

// API <-> core.
[[nodiscard]] Eigen::Vector3d FromProto(const fusion::v1::Point& p);
void ToProto(const Eigen::Vector3d& v, fusion::v1::Point* p);
[[nodiscard]] fusion::v1::VoxelState StateOf(double probability, const StateThresholds& t);
// Fills a voxel message from an octree node (null node: unknown).
void VoxelToProto(const octomap::OcTree& tree, const octomap::OcTreeKey& key, unsigned depth,
                  const octomap::OcTreeNode* node, const StateThresholds& t,
                  fusion::v1::Voxel* voxel);
void PlaneToProto(const Plane& plane, fusion::v1::Plane* out);
[[nodiscard]] HoughOptions HoughOptionsFromProto(const fusion::v1::FindPlanesRequest& request,
                                                 double resolution_m);

}  // namespace fusion::service
