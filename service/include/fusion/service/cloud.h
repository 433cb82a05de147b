// A validated point cloud on its way from DDS to the fusion worker, and the reasons a sample
// can be rejected before core sees it.
#pragma once

#include <Eigen/Geometry>
#include <array>
#include <chrono>
#include <cstdint>
#include <string>
#include <vector>

namespace fusion::service {

struct Cloud {
  std::string sensor_id;
  std::uint64_t sequence_number = 0;
  double stamp_s = 0.0;
  // Pose of the published frame in the world frame, as in the sample (mount not applied).
  Eigen::Isometry3d T_world_published = Eigen::Isometry3d::Identity();
  std::uint32_t width = 0;
  std::uint32_t height = 0;
  std::vector<float> xyz;                  // 3 * width * height, sensor frame, metres
  std::vector<std::uint8_t> beyond_range;  // empty or width * height
  // When the DDS sample arrived (for the DDS-to-queryable latency metric).
  std::chrono::steady_clock::time_point received_at{};
};

enum class RejectReason : int {
  kEmptySensorId = 0,
  kUnknownSensor,
  kPointCountMismatch,   // xyz length != 3 * width * height
  kBeyondRangeMismatch,  // beyond_range neither empty nor width * height
  kTooManyPoints,        // width * height above ingest.max_points (or zero)
  kNonFinitePose,
  kNonUnitQuaternion,
  kAbsurdTranslation,
  kOutsideMap,  // the pose lies beyond the map's keys (they would wrap around)
  // ROS 2 ingest: the conversion's reasons (fusion/ros2/points.h, Ros2Reject; same names) ...
  kRos2FieldsMissing,  // PointCloud2 without an x, y or z field
  kRos2FieldType,      // x, y or z not FLOAT32
  kRos2PointStep,      // point_step smaller than the x/y/z fields need
  kRos2DataShort,      // data shorter than row_step * height, or a row than its points
  kRos2TooLarge,       // more points than ingest.max_points
  kRos2Encoding,       // an image encoding that is not 16UC1 or 32FC1
  kRos2CameraInfo,     // the image does not fit the sensor's intrinsics (size, focal length 0)
  // ... a CameraInfo that disagrees with the configured pinhole intrinsics (the images of the
  // sensor are rejected until one agrees) ...
  kCameraInfoMismatch,
  // ... a depth image (or a fusion/points cloud) before the CameraInfo that gives its
  // sensor's intrinsics (a sensor configured without them), or while none received could make
  // a camera ...
  kNoCameraInfo,
  // ... and the pose look-up (fusion/core/transform_buffer.h, TransformStatus; same names).
  kNoTransform,      // header.frame_id not connected to the map frame within ros2.tf_wait_s
  kTransformTooOld,  // the stamp lies before the kept tf history (ros2.tf_history_s)
  kExtrapolation,    // no transform at or after the stamp within ros2.tf_wait_s
  kCount,
};
constexpr std::size_t kRejectReasonCount = static_cast<std::size_t>(RejectReason::kCount);

// Stable snake_case names, used in logs, counters and docs.
[[nodiscard]] const char* RejectReasonName(RejectReason reason);

}  // namespace fusion::service
