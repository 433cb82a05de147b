// The ROS 2 part of fusiond's configuration: the sensors with a ros2_topic, the map frame and
// tf (ros2_ingest.h); the map's output (ros2_output.h).
#include <cmath>
#include <set>

#include "fusion/service/conversions.h"
#include "fusion/service/ros2_ingest.h"
#include "fusion/service/ros2_output.h"

namespace fusion::service {
std::string DefaultCameraInfoTopic(const std::string& image_topic) {
  const auto slash = image_topic.rfind('/');
  return (slash == std::string::npos ? "" : image_topic.substr(0, slash + 1)) + "camera_info";
}

namespace {

constexpr double kMaxTfWaitS = 10.0;
constexpr double kMaxTfHistoryS = 3600.0;

// The ROS 2 fields of sensors[i]; nullopt when it has no ros2_topic.
StatusOr<std::optional<Ros2Sensor>> Ros2SensorFromConfig(const fusion::v1::SensorConfig& c) {
  if (c.ros2_topic().empty()) {
    if (!c.ros2_type().empty() || !c.ros2_camera_info_topic().empty() || c.ros2_reliable()) {
      return Status::Error(
          "ros2_topic: ros2_type, ros2_camera_info_topic and ros2_reliable "
          "need a ros2_topic");
    }
    return std::optional<Ros2Sensor>();
  }
  if (c.ros2_topic().front() == '/') {
    return Status::Error("ros2_topic: '" + c.ros2_topic() +
                         "' is a ROS 2 name; its DDS topic is 'rt" + c.ros2_topic() + "'");
  }
  Ros2Sensor sensor;
  sensor.sensor_id = c.id();
  sensor.topic = c.ros2_topic();
  sensor.reliable = c.ros2_reliable();
  if (c.ros2_type() == "depth_image") {
    sensor.depth_image = true;
  } else if (!c.ros2_type().empty() && c.ros2_type() != "point_cloud2") {
    return Status::Error("ros2_type: '" + c.ros2_type() + "' is not point_cloud2 or depth_image");
  }
  const auto setup = SensorSetupFromConfig(c);
  if (!setup.ok()) return setup.status();
  sensor.mount = setup->T_published_sensor;
  if (sensor.depth_image) {
    // Unset when the intrinsics come from the first CameraInfo (SensorSetupFromConfig).
    sensor.pinhole = setup->spec.pinhole;
    sensor.setup = *setup;
    sensor.camera_info_topic = c.ros2_camera_info_topic().empty()
                                   ? DefaultCameraInfoTopic(c.ros2_topic())
                                   : c.ros2_camera_info_topic();
    if (sensor.camera_info_topic.front() == '/') {
      return Status::Error("ros2_camera_info_topic: '" + sensor.camera_info_topic +
                           "' is a ROS 2 name; its DDS topic is 'rt" + sensor.camera_info_topic +
                           "'");
    }
  } else if (!c.ros2_camera_info_topic().empty()) {
    return Status::Error("ros2_camera_info_topic: only for ros2_type depth_image");
  }
  return std::optional<Ros2Sensor>(std::move(sensor));
}

Status TfOptionsFromConfig(const fusion::v1::Ros2Config& r, Ros2IngestOptions* options) {
  options->map_frame = r.map_frame().empty() ? "map" : Ros2FrameId(r.map_frame());
  if (options->map_frame.empty()) return Status::Error("ros2.map_frame: must name a frame");
  options->tf = !r.has_tf() || r.tf();
  if (r.has_tf_wait_s()) {
    if (!(r.tf_wait_s() >= 0.0 && r.tf_wait_s() <= kMaxTfWaitS)) {
      return Status::Error("ros2.tf_wait_s: must lie in [0, 10] seconds");
    }
    options->tf_wait_s = r.tf_wait_s();
  }
  if (r.tf_history_s() != 0.0) {
    if (!(r.tf_history_s() > 0.0 && r.tf_history_s() <= kMaxTfHistoryS)) {
      return Status::Error("ros2.tf_history_s: must lie in (0, 3600] seconds");
    }
    options->tf_history_s = r.tf_history_s();
  }
  return Status::Ok();
}

}  // namespace

StatusOr<Ros2IngestOptions> Ros2IngestOptionsFromConfig(const fusion::v1::ServiceConfig& config) {
  Ros2IngestOptions options;
  if (Status s = TfOptionsFromConfig(config.ros2(), &options); !s.ok()) return s;
  options.limits.max_points = config.ingest().max_points();
  options.limits.quaternion_tolerance = config.ingest().quaternion_tolerance();
  options.limits.max_abs_translation_m = config.ingest().max_abs_translation_m();
  options.limits.map_resolution_m = config.map().resolution_m();
  std::set<std::string> topics = {config.dds_topic(), "rt/tf", "rt/tf_static"};
  for (int i = 0; i < config.sensors_size(); ++i) {
    const std::string field = "sensors[" + std::to_string(i) + "].";
    auto sensor = Ros2SensorFromConfig(config.sensors(i));
    if (!sensor.ok()) return Status::Error(field + sensor.status().message());
    if (!sensor->has_value()) continue;
    const Ros2Sensor& s = **sensor;
    if (!topics.insert(s.topic).second) {
      return Status::Error(field + "ros2_topic: '" + s.topic +
                           "' is taken (another sensor, dds_topic or tf)");
    }
    if (s.depth_image && !topics.insert(s.camera_info_topic).second) {
      return Status::Error(field + "ros2_camera_info_topic: '" + s.camera_info_topic +
                           "' is taken (another sensor, dds_topic or tf)");
    }
    options.sensors.push_back(s);
  }
  return options;
}

StatusOr<Ros2OutputOptions> Ros2OutputOptionsFromConfig(const fusion::v1::ServiceConfig& config) {
  const auto ingest = Ros2IngestOptionsFromConfig(config);  // the one reading of map_frame
  if (!ingest.ok()) return ingest.status();
  const auto& r = config.ros2();
  Ros2OutputOptions options;
  options.rate_hz = r.octomap_rate_hz();
  options.thresholds = ThresholdsFromConfig(config.map());
  if (!std::isfinite(options.rate_hz) || options.rate_hz < 0.0 ||
      options.rate_hz > Ros2OutputOptions::kMaxRateHz) {
    return Status::Error("ros2.octomap_rate_hz: " + std::to_string(options.rate_hz) +
                         " is outside 0..100 (0 = off)");
  }
  options.binary = !r.has_octomap_binary() || r.octomap_binary();
  options.full = r.octomap_full();
  options.point_cloud_centers = r.point_cloud_centers();
  options.map_frame = ingest->map_frame;
  return options;
}

}  // namespace fusion::service
