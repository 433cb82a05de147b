#include "fusion/service/validation.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "fusion/core/local_grid.h"

namespace fusion::service {

const char* RejectReasonName(RejectReason reason) {
  switch (reason) {
    case RejectReason::kEmptySensorId:
      return "empty_sensor_id";
    case RejectReason::kUnknownSensor:
      return "unknown_sensor";
    case RejectReason::kPointCountMismatch:
      return "point_count_mismatch";
    case RejectReason::kBeyondRangeMismatch:
      return "beyond_range_mismatch";
    case RejectReason::kTooManyPoints:
      return "absurd_point_count";
    case RejectReason::kNonFinitePose:
      return "non_finite_pose";
    case RejectReason::kNonUnitQuaternion:
      return "non_unit_quaternion";
    case RejectReason::kAbsurdTranslation:
      return "absurd_translation";
    case RejectReason::kOutsideMap:
      return "outside_map";
    case RejectReason::kRos2FieldsMissing:
      return "fields_missing";
    case RejectReason::kRos2FieldType:
      return "field_type";
    case RejectReason::kRos2PointStep:
      return "point_step";
    case RejectReason::kRos2DataShort:
      return "data_short";
    case RejectReason::kRos2TooLarge:
      return "too_large";
    case RejectReason::kRos2Encoding:
      return "encoding";
    case RejectReason::kRos2CameraInfo:
      return "camera_info";
    case RejectReason::kCameraInfoMismatch:
      return "camera_info_mismatch";
    case RejectReason::kNoCameraInfo:
      return "no_camera_info";
    case RejectReason::kNoTransform:
      return "no_transform";
    case RejectReason::kTransformTooOld:
      return "transform_too_old";
    case RejectReason::kExtrapolation:
      return "extrapolation";
    case RejectReason::kCount:
      break;
  }
  return "unknown_reason";
}

std::string LoggableText(std::string_view text, std::size_t max_bytes) {
  std::string out;
  const std::size_t kept = std::min(text.size(), max_bytes);
  for (std::size_t i = 0; i < kept; ++i) {
    const auto c = static_cast<unsigned char>(text[i]);
    if (c == '\n') {
      out += "\\n";
    } else if (c == '\\') {
      out += "\\\\";
    } else if (c < 0x20 || c >= 0x7f) {
      static const char kHex[] = "0123456789abcdef";
      out += "\\x";
      out += kHex[c >> 4];
      out += kHex[c & 15];
    } else {
      out += static_cast<char>(c);
    }
  }
  if (kept < text.size()) out += "...(" + std::to_string(text.size()) + " bytes)";
  return out;
}

std::optional<RejectReason> ValidateSensorId(
    const char* sensor_id, const std::function<bool(const std::string&)>& is_known_sensor,
    std::string* detail) {
  if (sensor_id == nullptr || sensor_id[0] == '\0') {
    *detail = "empty sensor_id";
    return RejectReason::kEmptySensorId;
  }
  const std::string id = sensor_id;
  if (!is_known_sensor(id)) {
    *detail = "sensor '" + LoggableText(id) + "' is not configured";
    return RejectReason::kUnknownSensor;
  }
  return std::nullopt;
}

std::optional<RejectReason> ValidateSample(
    const fusion_dds_PointCloud& sample, const IngestLimits& limits,
    const std::function<bool(const std::string&)>& is_known_sensor, std::string* detail) {
  if (auto reason = ValidateSensorId(sample.sensor_id, is_known_sensor, detail)) return reason;
  // 64-bit products: width * height of two uint32 cannot overflow.
  const std::uint64_t points = std::uint64_t{sample.width} * sample.height;
  if (points == 0 || points > limits.max_points) {
    *detail = "width * height = " + std::to_string(points) + " points (limit " +
              std::to_string(limits.max_points) + ")";
    return RejectReason::kTooManyPoints;
  }
  if (sample.xyz._length != 3 * points || sample.xyz._buffer == nullptr) {
    *detail = "xyz has " + std::to_string(sample.xyz._length) + " values, expected 3 * " +
              std::to_string(points);
    return RejectReason::kPointCountMismatch;
  }
  if (sample.beyond_range._length != 0 &&
      (sample.beyond_range._length != points || sample.beyond_range._buffer == nullptr)) {
    *detail = "beyond_range has " + std::to_string(sample.beyond_range._length) +
              " flags, expected 0 or " + std::to_string(points);
    return RejectReason::kBeyondRangeMismatch;
  }
  const fusion_dds_Pose& p = sample.T_world_sensor;
  const double values[] = {p.tx, p.ty, p.tz, p.qx, p.qy, p.qz, p.qw};
  for (double v : values) {
    if (!std::isfinite(v)) {
      *detail = "pose has a NaN or infinite component";
      return RejectReason::kNonFinitePose;
    }
  }
  const double norm = std::sqrt(p.qx * p.qx + p.qy * p.qy + p.qz * p.qz + p.qw * p.qw);
  if (std::abs(norm - 1.0) > limits.quaternion_tolerance) {
    *detail = "quaternion norm " + std::to_string(norm) + " is not 1";
    return RejectReason::kNonUnitQuaternion;
  }
  for (double t : {p.tx, p.ty, p.tz}) {
    if (std::abs(t) > limits.max_abs_translation_m) {
      *detail = "translation component " + std::to_string(t) + " m beyond +-" +
                std::to_string(limits.max_abs_translation_m) + " m";
      return RejectReason::kAbsurdTranslation;
    }
  }
  if (limits.map_resolution_m > 0.0 &&
      !InsideMap(Eigen::Vector3d(p.tx, p.ty, p.tz), limits.map_resolution_m)) {
    *detail = "position (" + std::to_string(p.tx) + ", " + std::to_string(p.ty) + ", " +
              std::to_string(p.tz) + ") m lies beyond the map's +-" +
              std::to_string(MapHalfExtentM(limits.map_resolution_m)) + " m at " +
              std::to_string(limits.map_resolution_m) + " m voxels";
    return RejectReason::kOutsideMap;
  }
  return std::nullopt;
}

std::optional<RejectReason> ValidateCloud(
    const Cloud& cloud, const IngestLimits& limits,
    const std::function<bool(const std::string&)>& is_known_sensor, std::string* detail) {
  // A view of the cloud as the DDS sample it could have been: one set of rules for both.
  const Eigen::Quaterniond q(cloud.T_world_published.linear());
  const Eigen::Vector3d t = cloud.T_world_published.translation();
  fusion_dds_PointCloud view{};
  view.sensor_id = const_cast<char*>(cloud.sensor_id.c_str());
  view.T_world_sensor = {t.x(), t.y(), t.z(), q.x(), q.y(), q.z(), q.w()};
  view.width = cloud.width;
  view.height = cloud.height;
  view.xyz._buffer = const_cast<float*>(cloud.xyz.data());
  view.xyz._length = view.xyz._maximum = static_cast<std::uint32_t>(
      std::min<std::size_t>(cloud.xyz.size(), std::numeric_limits<std::uint32_t>::max()));
  view.beyond_range._buffer = const_cast<std::uint8_t*>(cloud.beyond_range.data());
  view.beyond_range._length = view.beyond_range._maximum = static_cast<std::uint32_t>(
      std::min<std::size_t>(cloud.beyond_range.size(), std::numeric_limits<std::uint32_t>::max()));
  return ValidateSample(view, limits, is_known_sensor, detail);
}

}  // namespace fusion::service
