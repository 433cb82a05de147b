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
  kCount,
};
constexpr std::size_t kRejectReasonCount = static_cast<std::size_t>(RejectReason::kCount);

// Stable snake_case names, used in logs, counters and docs.
[[nodiscard]] const char* RejectReasonName(RejectReason reason);

}  // namespace fusion::service
