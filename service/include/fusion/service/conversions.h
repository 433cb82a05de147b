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
#include "fusion/ros2/messages.h"
#include "fusion/service/cloud.h"
#include "fusion/v1/config.pb.h"
#include "fusion/v1/map_service.pb.h"
#include "fusion_dds.h"
#include "sensor_msgs.h"
#include "tf2_msgs.h"

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
  // A depth_image sensor configured without intrinsics (neither a pinhole preset nor a pinhole
  // block that gives them): its beams are the pixels of the first CameraInfo it receives, at
  // camera_stride (SpecFromCameraInfo); until then spec has no beams (cols = rows = 0).
  bool intrinsics_from_camera_info = false;
  int camera_stride = 1;
};

// Thresholds that turn an occupancy probability into a state.
// Default: core's one threshold, no dead band (fusiond deploys one: config.cc, DefaultConfig).
struct StateThresholds {
  double occupied = WorldMapOptions::kDefaultOccupancyThreshold;  // p >= occupied: occupied
  double free = WorldMapOptions::kDefaultOccupancyThreshold;      // p < free: free (else unknown)
};

// Config -> core. An error names the field (relative to the message).
[[nodiscard]] StatusOr<SensorSetup> SensorSetupFromConfig(const fusion::v1::SensorConfig& c);
// The spec of a sensor whose intrinsics come from its CameraInfo (intrinsics_from_camera_info):
// one beam per pixel (or per camera_stride pixels) of the image K describes (fx = K[0],
// fy = K[4], cx = K[2], cy = K[5], width x height), checked as a configured pinhole block is.
[[nodiscard]] StatusOr<SensorSpec> SpecFromCameraInfo(const SensorSetup& setup,
                                                      const ros2::CameraInfo& info);
[[nodiscard]] StatusOr<WorldMapOptions> WorldMapOptionsFromConfig(const fusion::v1::MapConfig& c);
[[nodiscard]] StateThresholds ThresholdsFromConfig(const fusion::v1::MapConfig& c);
// A transform whose quaternion is all zero is the identity.
[[nodiscard]] Eigen::Isometry3d IsometryFromConfig(const fusion::v1::Transform& t);

// DDS -> core. The sample must have passed ValidateSample.
[[nodiscard]] Eigen::Isometry3d IsometryFromDds(const fusion_dds_Pose& pose);
[[nodiscard]] Cloud CloudFromDds(const fusion_dds_PointCloud& sample);

// ROS 2 DDS samples (idl/ros2/) -> the ROS 2 wire library's messages (fusion/ros2/messages.h).
// The `data` views point into the sample, nothing is copied: the sample must outlive them.
[[nodiscard]] ros2::PointCloud2 Ros2FromDds(const sensor_msgs_msg_dds__PointCloud2_& sample);
[[nodiscard]] ros2::Image Ros2FromDds(const sensor_msgs_msg_dds__Image_& sample);
[[nodiscard]] ros2::CameraInfo Ros2FromDds(const sensor_msgs_msg_dds__CameraInfo_& sample);
[[nodiscard]] ros2::TFMessage Ros2FromDds(const tf2_msgs_msg_dds__TFMessage_& sample);
// T_parent_child of a tf transform; the quaternion normalised (a zero one gives NaN).
[[nodiscard]] Eigen::Isometry3d IsometryFromRos2(const ros2::Transform& transform);
// A tf frame id as tf2 compares them: without a leading '/'.
[[nodiscard]] std::string Ros2FrameId(const std::string& frame_id);
// A converted ROS 2 message (xyz in the message's frame, metres) as a Cloud of `sensor_id`:
// T_world_published = T_map_frame; with T_sensor_frame (the inverse mount, when the mount is
// not the identity) the points are moved into the sensor's frame, since the worker applies
// the mount to the pose and takes the points as the sensor's.
[[nodiscard]] Cloud CloudFromRos2(const std::string& sensor_id, std::uint64_t sequence_number,
                                  double stamp_s, const Eigen::Isometry3d& T_map_frame,
                                  const Eigen::Isometry3d* T_sensor_frame, std::uint32_t width,
                                  std::uint32_t height, std::vector<float> xyz);

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
