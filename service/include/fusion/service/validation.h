// Checks every DDS sample before anything of it reaches core.
#pragma once

#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <string_view>

#include "fusion/service/cloud.h"
#include "fusion_dds.h"

namespace fusion::service {

struct IngestLimits {
  std::uint32_t max_points = 4'000'000;
  double quaternion_tolerance = 1e-3;  // | |q| - 1 | above this is rejected
  double max_abs_translation_m = 1e5;  // per axis
  // > 0: a pose whose position lies beyond the map's keys at this resolution (core's InsideMap:
  // +-32768 voxels a side, +-655 m at 2 cm) is rejected as outside_map.
  double map_resolution_m = 0.0;
};

// Untrusted text (a sample's sensor id, a topic name) as it may appear in a log line: control
// characters, backslashes and bytes outside printable ASCII escaped (\n, \xNN), at most
// max_bytes of the original kept ("...(N bytes)" says how long it was).
[[nodiscard]] std::string LoggableText(std::string_view text, std::size_t max_bytes = 64);

// The sensor id check alone (empty, or not configured): DDS ingest applies it before the
// reader keeps any state for a sample, so unknown ids cost nothing however many there are.
[[nodiscard]] std::optional<RejectReason> ValidateSensorId(
    const char* sensor_id, const std::function<bool(const std::string&)>& is_known_sensor,
    std::string* detail);

// std::nullopt if the sample may be converted and integrated; otherwise the reason, with
// *detail saying what exactly was wrong (for the log).
[[nodiscard]] std::optional<RejectReason> ValidateSample(
    const fusion_dds_PointCloud& sample, const IngestLimits& limits,
    const std::function<bool(const std::string&)>& is_known_sensor, std::string* detail);

// The same checks on a cloud converted from another wire type (a ROS 2 message): its sizes and
// T_world_published, by ValidateSample's rules.
[[nodiscard]] std::optional<RejectReason> ValidateCloud(
    const Cloud& cloud, const IngestLimits& limits,
    const std::function<bool(const std::string&)>& is_known_sensor, std::string* detail);

}  // namespace fusion::service
