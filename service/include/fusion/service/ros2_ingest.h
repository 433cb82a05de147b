// ROS 2 ingest: readers with ROS 2's topic and type names (sensor_msgs PointCloud2, depth Image
// with CameraInfo; tf2_msgs TFMessage on rt/tf and rt/tf_static) served by one thread. Each
// message is converted to points by the ROS 2 wire library (fusion/ros2/points.h), posed by tf
// (the chain from header.frame_id to the map frame at header.stamp; a message whose transform
// has not arrived yet waits, parked, up to tf_wait_s) and then validated, counted and queued
// exactly like a fusion::dds::PointCloud (ValidateCloud, IngestQueues).
#pragma once

#include <dds/dds.h>

#include <Eigen/Geometry>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <deque>
#include <functional>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "fusion/core/sensor.h"
#include "fusion/core/status.h"
#include "fusion/core/transform_buffer.h"
#include "fusion/ros2/messages.h"
#include "fusion/service/conversions.h"
#include "fusion/service/ingest_queues.h"
#include "fusion/service/rejection_log.h"
#include "fusion/service/validation.h"
#include "fusion/v1/config.pb.h"
#include "sensor_msgs.h"
#include "tf2_msgs.h"

namespace fusion::service {

// One configured sensor read from a ROS 2 topic.
struct Ros2Sensor {
  std::string sensor_id;
  std::string topic;              // e.g. "rt/camera/depth/points"
  bool depth_image = false;       // sensor_msgs/Image (+ CameraInfo), else PointCloud2
  std::string camera_info_topic;  // depth images
  bool reliable = false;          // reliable reader, lossless queueing; else sensor-data QoS
  // The sensor's mount: with tf, T_frame_sensor (message frame -> sensor frame); without tf,
  // the sensor's fixed pose in the map frame.
  Eigen::Isometry3d mount = Eigen::Isometry3d::Identity();
  // Depth images: the camera's intrinsics, configured; unset when they come from the first
  // CameraInfo (then `setup` is the sensor as configured, for SpecFromCameraInfo).
  std::optional<PinholeIntrinsics> pinhole;
  SensorSetup setup;
};

struct Ros2IngestOptions {
  static constexpr double kDefaultTfWaitS = 0.2;
  static constexpr double kDefaultTfHistoryS = 10.0;
  // Clouds of one sensor that wait for their transform at once (the oldest gives up first).
  static constexpr std::size_t kMaxParkedPerSensor = 16;

  std::vector<Ros2Sensor> sensors;
  std::string map_frame = "map";
  bool tf = true;
  double tf_wait_s = kDefaultTfWaitS;
  double tf_history_s = kDefaultTfHistoryS;
  IngestLimits limits;
  std::chrono::milliseconds log_interval{1000};
};

// The ROS 2 part of a configuration: every sensor with a ros2_topic, the map frame and tf.
// An error names the field ("sensors[1].ros2_type: ...", "ros2.tf_wait_s: ...").
[[nodiscard]] StatusOr<Ros2IngestOptions> Ros2IngestOptionsFromConfig(
    const fusion::v1::ServiceConfig& config);
// The image topic's sibling "camera_info": rt/camera/depth/image_raw ->
// rt/camera/depth/camera_info.
[[nodiscard]] std::string DefaultCameraInfoTopic(const std::string& image_topic);

class Ros2Ingest {
 public:
  // Gives a camera configured without intrinsics the beams of its first CameraInfo
  // (FusionWorker::DefineSensor); an error leaves it waiting.
  using DefineSensor = std::function<Status(const std::string& sensor_id, const SensorSpec& spec)>;

  Ros2Ingest(IngestQueues* queues, Ros2IngestOptions options, DefineSensor define_sensor = {});
  ~Ros2Ingest();
  Ros2Ingest(const Ros2Ingest&) = delete;
  Ros2Ingest& operator=(const Ros2Ingest&) = delete;

  // Creates the topics and readers in `participant` and starts the thread.
  [[nodiscard]] Status Start(dds_entity_t participant);
  // Stops the thread (clouds still waiting for a transform are looked up a last time) and
  // deletes the readers.
  void Stop();

 private:
  enum class Kind { kPointCloud2, kImage, kCameraInfo, kTf, kTfStatic };
  struct Reader {
    Kind kind;
    std::size_t sensor;  // index into sensors_ (clouds, images, camera infos)
    std::string topic;
    dds_entity_t reader = 0;
    MatchedWriters* matched = nullptr;  // GetStats' count, shared with the points topic's reader
  };
  struct Parked {
    Cloud cloud;
    std::string frame_id;
    std::chrono::steady_clock::time_point deadline;
  };
  struct SensorState {
    Ros2Sensor config;
    std::uint64_t sequence_number = 0;
    std::string camera_info_mismatch;  // empty: the last CameraInfo agreed (or none came yet)
    std::string no_camera_info;        // why a camera without intrinsics has none yet
    std::deque<Parked> parked;         // waiting for their transform, oldest first
  };

  // A reader's listener (arg: its Reader): logs, and adds the change to GetStats' count.
  static void OnWritersMatched(dds_entity_t reader, dds_subscription_matched_status_t status,
                               void* arg);
  [[nodiscard]] Status AddReader(dds_entity_t participant, Kind kind, std::size_t sensor,
                                 const std::string& topic, bool reliable);
  void Loop();
  void TakeAll(const Reader& reader);
  void OnPointCloud2(SensorState& sensor, const sensor_msgs_msg_dds__PointCloud2_& sample);
  void OnImage(SensorState& sensor, const sensor_msgs_msg_dds__Image_& sample);
  void OnCameraInfo(SensorState& sensor, const sensor_msgs_msg_dds__CameraInfo_& sample);
  // A camera configured without intrinsics takes them from `info` (its first usable one).
  void TakeIntrinsics(SensorState& sensor, const ros2::CameraInfo& info);
  void OnTf(const tf2_msgs_msg_dds__TFMessage_& sample, bool is_static);
  // A converted message's points as a cloud of the sensor, handed to Place.
  void Deliver(SensorState& sensor, const ros2::Header& header, std::uint32_t width,
               std::uint32_t height, std::vector<float> xyz,
               std::chrono::steady_clock::time_point received_at);
  // A converted message: queued at its pose, parked until its transform comes, or rejected.
  void Place(SensorState& sensor, Cloud cloud, const std::string& frame_id);
  // The parked clouds whose transform came are queued, the ones out of time rejected (all of
  // them with `give_up_all`), in order per sensor.
  void RetryParked(bool give_up_all);
  // T_map_frame of a cloud; kOk when found.
  TransformStatus PoseOf(const std::string& frame_id, double stamp_s, Eigen::Isometry3d* T) const;
  void Queue(SensorState& sensor, Cloud cloud, const Eigen::Isometry3d& T_map_frame);
  void Reject(const SensorState& sensor, RejectReason reason, const std::string& detail);
  [[nodiscard]] dds_duration_t WaitTimeout() const;

  IngestQueues* queues_;
  Ros2IngestOptions options_;
  DefineSensor define_sensor_;
  std::vector<SensorState> sensors_;
  std::deque<Reader> readers_;  // stable addresses: listeners hold them
  TransformBuffer tf_;          // the ingest thread's alone
  dds_entity_t waitset_ = 0;
  dds_entity_t stop_condition_ = 0;
  std::atomic<bool> stop_{false};
  std::thread thread_;
  RejectionLog log_;
  std::chrono::steady_clock::time_point last_tf_warning_{};
};

}  // namespace fusion::service
