#include "fusion/service/ros2_ingest.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>

#include "fusion/ros2/points.h"
#include "fusion/service/conversions.h"

namespace fusion::service {
namespace {

constexpr int kMaxSamplesPerTake = 16;
// A CameraInfo agrees with the configured intrinsics when its focal lengths are within this
// fraction and its principal point within this many pixels of them.
constexpr double kFocalTolerance = 0.005;
constexpr double kPrincipalPointTolerancePx = 1.0;

std::string DdsError(const char* call, const std::string& topic, dds_return_t rc) {
  return std::string(call) + " '" + topic + "': " + dds_strretcode(rc);
}

RejectReason ReasonOf(ros2::Ros2Reject reject) {
  switch (reject) {
    case ros2::Ros2Reject::kFieldsMissing:
      return RejectReason::kRos2FieldsMissing;
    case ros2::Ros2Reject::kFieldType:
      return RejectReason::kRos2FieldType;
    case ros2::Ros2Reject::kPointStep:
      return RejectReason::kRos2PointStep;
    case ros2::Ros2Reject::kDataShort:
      return RejectReason::kRos2DataShort;
    case ros2::Ros2Reject::kTooLarge:
      return RejectReason::kRos2TooLarge;
    case ros2::Ros2Reject::kEncoding:
      return RejectReason::kRos2Encoding;
    case ros2::Ros2Reject::kCameraInfo:
    case ros2::Ros2Reject::kNone:
      break;
  }
  return RejectReason::kRos2CameraInfo;
}

RejectReason ReasonOf(TransformStatus status) {
  switch (status) {
    case TransformStatus::kTooOld:
      return RejectReason::kTransformTooOld;
    case TransformStatus::kExtrapolation:
      return RejectReason::kExtrapolation;
    case TransformStatus::kOk:
    case TransformStatus::kNoTransform:
      break;
  }
  return RejectReason::kNoTransform;
}

// Why a CameraInfo does not describe the configured camera; empty when it does.
std::string CameraInfoMismatch(const ros2::CameraInfo& info, const PinholeIntrinsics& k) {
  const auto near_focal = [](double a, double b) { return std::abs(a - b) <= kFocalTolerance * b; };
  const auto near_px = [](double a, double b) {
    return std::abs(a - b) <= kPrincipalPointTolerancePx;
  };
  if (info.width != static_cast<std::uint32_t>(k.width_px) ||
      info.height != static_cast<std::uint32_t>(k.height_px)) {
    return fmt::format("CameraInfo is {} x {} pixels, the configured pinhole {} x {}", info.width,
                       info.height, k.width_px, k.height_px);
  }
  if (!near_focal(info.k[0], k.fx_px) || !near_focal(info.k[4], k.fy_px) ||
      !near_px(info.k[2], k.cx_px) || !near_px(info.k[5], k.cy_px)) {
    return fmt::format(
        "CameraInfo K (fx {}, fy {}, cx {}, cy {}) disagrees with the configured pinhole (fx {}, "
        "fy {}, cx {}, cy {})",
        info.k[0], info.k[4], info.k[2], info.k[5], k.fx_px, k.fy_px, k.cx_px, k.cy_px);
  }
  return "";
}

// Takes every sample the reader holds and hands the valid ones to `handle` (on loan).
template <class Sample, class Handle>
void TakeEach(dds_entity_t reader, const std::string& topic, Handle&& handle) {
  for (;;) {
    void* samples[kMaxSamplesPerTake] = {};
    dds_sample_info_t infos[kMaxSamplesPerTake];
    const dds_return_t n = dds_take(reader, samples, infos, kMaxSamplesPerTake, kMaxSamplesPerTake);
    if (n < 0) {
      spdlog::error("ros2: dds_take '{}': {}", topic, dds_strretcode(n));
      return;
    }
    for (int i = 0; i < n; ++i) {
      if (!infos[i].valid_data) continue;
      try {
        handle(*static_cast<const Sample*>(samples[i]));
      } catch (const std::exception& e) {
        spdlog::error("ros2: message on '{}' dropped: {}", LoggableText(topic), e.what());
      }
    }
    if (n > 0) dds_return_loan(reader, samples, n);
    if (n < kMaxSamplesPerTake) return;
  }
}

}  // namespace

Ros2Ingest::Ros2Ingest(IngestQueues* queues, Ros2IngestOptions options, DefineSensor define_sensor)
    : queues_(queues),
      options_(std::move(options)),
      define_sensor_(std::move(define_sensor)),
      tf_(options_.tf_history_s),
      log_(options_.log_interval) {
  for (const Ros2Sensor& s : options_.sensors) {
    const std::string waiting = "no CameraInfo on '" + s.camera_info_topic + "' yet";
    sensors_.push_back({s, 0, "", s.depth_image ? waiting : "", {}});
  }
}

Ros2Ingest::~Ros2Ingest() { Stop(); }

// The count GetStats reports is shared by every reader (and the points topic's): each adds its
// changes.
void Ros2Ingest::OnWritersMatched(dds_entity_t, const dds_subscription_matched_status_t status,
                                  void* arg) {
  const Reader& r = *static_cast<const Reader*>(arg);
  r.matched->current.fetch_add(static_cast<std::uint32_t>(status.current_count_change));
  r.matched->total.fetch_add(static_cast<std::uint64_t>(status.total_count_change));
  spdlog::info("ros2: {} writer(s) matched on '{}' ({} since the start)", status.current_count,
               LoggableText(r.topic), status.total_count);
}

Status Ros2Ingest::AddReader(dds_entity_t participant, Kind kind, std::size_t sensor,
                             const std::string& topic_name, bool reliable) {
  const dds_topic_descriptor_t* type = &sensor_msgs_msg_dds__PointCloud2__desc;
  if (kind == Kind::kImage) type = &sensor_msgs_msg_dds__Image__desc;
  if (kind == Kind::kCameraInfo) type = &sensor_msgs_msg_dds__CameraInfo__desc;
  if (kind == Kind::kTf || kind == Kind::kTfStatic) type = &tf2_msgs_msg_dds__TFMessage__desc;
  const dds_entity_t topic =
      dds_create_topic(participant, type, topic_name.c_str(), nullptr, nullptr);
  if (topic < 0) return Status::Error(DdsError("dds_create_topic", topic_name, topic));
  // QoS as ROS 2 publishes them: sensor data (best effort, keep last 5, volatile); tf (reliable,
  // keep last 100); tf_static transient local, so transforms published before fusiond started
  // arrive. Readers of tf_static keep 100 (ROS 2's writers keep 1): several static broadcasters
  // answering one new reader at once lose nothing.
  dds_qos_t* qos = dds_create_qos();
  if (reliable) {
    dds_qset_reliability(qos, DDS_RELIABILITY_RELIABLE, DDS_SECS(1));
  } else {
    dds_qset_reliability(qos, DDS_RELIABILITY_BEST_EFFORT, 0);
  }
  const bool is_tf = kind == Kind::kTf || kind == Kind::kTfStatic;
  dds_qset_history(qos, DDS_HISTORY_KEEP_LAST, is_tf ? 100 : reliable ? 10 : 5);
  dds_qset_durability(
      qos, kind == Kind::kTfStatic ? DDS_DURABILITY_TRANSIENT_LOCAL : DDS_DURABILITY_VOLATILE);
  Reader& r =
      readers_.emplace_back(Reader{kind, sensor, topic_name, 0, &queues_->matched_writers()});
  dds_listener_t* listener = dds_create_listener(&r);
  dds_lset_subscription_matched(listener, &OnWritersMatched);
  r.reader = dds_create_reader(participant, topic, qos, listener);
  dds_delete_listener(listener);
  dds_delete_qos(qos);
  if (r.reader < 0) return Status::Error(DdsError("dds_create_reader", topic_name, r.reader));
  const dds_entity_t condition = dds_create_readcondition(r.reader, DDS_ANY_STATE);
  if (condition < 0) {
    return Status::Error(DdsError("dds_create_readcondition", topic_name, condition));
  }
  if (const dds_return_t rc = dds_waitset_attach(waitset_, condition, 0); rc != DDS_RETCODE_OK) {
    return Status::Error(DdsError("dds_waitset_attach", topic_name, rc));
  }
  return Status::Ok();
}

Status Ros2Ingest::Start(dds_entity_t participant) {
  if (sensors_.empty()) return Status::Ok();
  waitset_ = dds_create_waitset(participant);
  if (waitset_ < 0) return Status::Error(DdsError("dds_create_waitset", "", waitset_));
  stop_condition_ = dds_create_guardcondition(participant);
  if (stop_condition_ < 0) {
    return Status::Error(DdsError("dds_create_guardcondition", "", stop_condition_));
  }
  if (const dds_return_t rc = dds_waitset_attach(waitset_, stop_condition_, 1);
      rc != DDS_RETCODE_OK) {
    return Status::Error(DdsError("dds_waitset_attach", "", rc));
  }
  // Taken in this order each round: transforms and camera infos before the clouds they serve.
  if (options_.tf) {
    if (Status s = AddReader(participant, Kind::kTf, 0, "rt/tf", true); !s.ok()) return s;
    if (Status s = AddReader(participant, Kind::kTfStatic, 0, "rt/tf_static", true); !s.ok()) {
      return s;
    }
  }
  for (std::size_t i = 0; i < sensors_.size(); ++i) {
    const Ros2Sensor& s = sensors_[i].config;
    if (!s.depth_image) continue;
    if (Status st = AddReader(participant, Kind::kCameraInfo, i, s.camera_info_topic, s.reliable);
        !st.ok()) {
      return st;
    }
  }
  for (std::size_t i = 0; i < sensors_.size(); ++i) {
    const Ros2Sensor& s = sensors_[i].config;
    const Kind kind = s.depth_image ? Kind::kImage : Kind::kPointCloud2;
    if (Status st = AddReader(participant, kind, i, s.topic, s.reliable); !st.ok()) return st;
    spdlog::info("ros2: sensor '{}' reads {} on '{}' ({}){}", LoggableText(s.sensor_id),
                 s.depth_image ? "sensor_msgs/Image" : "sensor_msgs/PointCloud2",
                 LoggableText(s.topic), s.reliable ? "reliable" : "sensor data",
                 options_.tf ? " posed by tf in '" + LoggableText(options_.map_frame) + "'"
                             : " at its mount");
  }
  thread_ = std::thread([this] { Loop(); });
  return Status::Ok();
}

void Ros2Ingest::Stop() {
  if (thread_.joinable()) {
    stop_ = true;
    dds_set_guardcondition(stop_condition_, true);
    thread_.join();
  }
  // Deleting a reader deletes its read condition; the topics go with the participant.
  for (Reader& r : readers_) {
    if (r.reader > 0) dds_delete(r.reader);
    r.reader = 0;
  }
  for (dds_entity_t* e : {&waitset_, &stop_condition_}) {
    if (*e > 0) dds_delete(*e);
    *e = 0;
  }
}

dds_duration_t Ros2Ingest::WaitTimeout() const {
  auto timeout = std::chrono::steady_clock::duration(std::chrono::milliseconds(500));
  const auto now = std::chrono::steady_clock::now();
  for (const SensorState& s : sensors_) {
    if (!s.parked.empty()) timeout = std::min(timeout, s.parked.front().deadline - now);
  }
  const auto ns = std::chrono::duration_cast<std::chrono::nanoseconds>(timeout).count();
  return std::max<dds_duration_t>(ns, DDS_MSECS(1));
}

void Ros2Ingest::Loop() {
  while (!stop_) {
    const dds_return_t woken = dds_waitset_wait(waitset_, nullptr, 0, WaitTimeout());
    if (woken < 0) spdlog::error("ros2: dds_waitset_wait: {}", dds_strretcode(woken));
    for (const Reader& r : readers_) TakeAll(r);
    RetryParked(false);
  }
  RetryParked(true);
}

void Ros2Ingest::TakeAll(const Reader& r) {
  switch (r.kind) {
    case Kind::kTf:
    case Kind::kTfStatic:
      TakeEach<tf2_msgs_msg_dds__TFMessage_>(
          r.reader, r.topic, [&](const auto& sample) { OnTf(sample, r.kind == Kind::kTfStatic); });
      break;
    case Kind::kCameraInfo:
      TakeEach<sensor_msgs_msg_dds__CameraInfo_>(
          r.reader, r.topic, [&](const auto& sample) { OnCameraInfo(sensors_[r.sensor], sample); });
      break;
    case Kind::kImage:
      TakeEach<sensor_msgs_msg_dds__Image_>(
          r.reader, r.topic, [&](const auto& sample) { OnImage(sensors_[r.sensor], sample); });
      break;
    case Kind::kPointCloud2:
      TakeEach<sensor_msgs_msg_dds__PointCloud2_>(r.reader, r.topic, [&](const auto& sample) {
        OnPointCloud2(sensors_[r.sensor], sample);
      });
      break;
  }
}

void Ros2Ingest::OnTf(const tf2_msgs_msg_dds__TFMessage_& sample, bool is_static) {
  const ros2::TFMessage msg = Ros2FromDds(sample);
  for (const ros2::TransformStamped& t : msg.transforms) {
    const auto& q = t.transform.rotation;
    const double norm = std::sqrt(q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w);
    if (!(std::abs(norm - 1.0) <= 0.01)) {
      // tf2 refuses these too; one warning a second at most.
      const auto now = std::chrono::steady_clock::now();
      if (now - last_tf_warning_ >= options_.log_interval) {
        last_tf_warning_ = now;
        spdlog::warn("ros2: transform '{}' -> '{}' ignored: quaternion norm {}",
                     LoggableText(t.header.frame_id), LoggableText(t.child_frame_id), norm);
      }
      continue;
    }
    tf_.Add(Ros2FrameId(t.header.frame_id), Ros2FrameId(t.child_frame_id), t.header.stamp.seconds(),
            IsometryFromRos2(t.transform), is_static);
  }
}

void Ros2Ingest::OnCameraInfo(SensorState& sensor, const sensor_msgs_msg_dds__CameraInfo_& sample) {
  const ros2::CameraInfo info = Ros2FromDds(sample);
  if (!sensor.config.pinhole) {
    TakeIntrinsics(sensor, info);
    return;
  }
  const std::string mismatch = CameraInfoMismatch(info, *sensor.config.pinhole);
  if (mismatch != sensor.camera_info_mismatch) {
    if (mismatch.empty()) {
      spdlog::info("ros2: sensor '{}': CameraInfo agrees with the configured intrinsics again",
                   LoggableText(sensor.config.sensor_id));
    } else {
      spdlog::warn("ros2: sensor '{}': {}; its images are rejected until one agrees",
                   LoggableText(sensor.config.sensor_id), mismatch);
    }
  }
  sensor.camera_info_mismatch = mismatch;
}

void Ros2Ingest::TakeIntrinsics(SensorState& sensor, const ros2::CameraInfo& info) {
  const std::string& id = sensor.config.sensor_id;
  const auto spec = SpecFromCameraInfo(sensor.config.setup, info);
  Status defined = spec.ok() ? Status::Ok() : spec.status();
  if (defined.ok()) {
    defined = define_sensor_ ? define_sensor_(id, *spec) : Status::Error("no worker to tell");
  }
  if (!defined.ok()) {
    const std::string problem = "the CameraInfo received makes no camera: " + defined.message();
    if (problem != sensor.no_camera_info) {
      spdlog::warn("ros2: sensor '{}': {}; its images are rejected until one does",
                   LoggableText(id), problem);
    }
    sensor.no_camera_info = problem;
    return;
  }
  const PinholeIntrinsics& k = *spec->pinhole;
  sensor.config.pinhole = k;
  sensor.no_camera_info.clear();
  spdlog::info(
      "ros2: sensor '{}': intrinsics from its CameraInfo: fx {} fy {} cx {} cy {} px, "
      "{} x {} pixels, stride {}: {} x {} beams",
      LoggableText(id), k.fx_px, k.fy_px, k.cx_px, k.cy_px, k.width_px, k.height_px, k.stride,
      spec->cols, spec->rows);
}

void Ros2Ingest::OnPointCloud2(SensorState& sensor,
                               const sensor_msgs_msg_dds__PointCloud2_& sample) {
  const auto received_at = std::chrono::steady_clock::now();
  const ros2::PointCloud2 msg = Ros2FromDds(sample);
  std::vector<float> xyz;
  std::string detail;
  const auto reject = ros2::PointsFromPointCloud2(msg, options_.limits.max_points, &xyz, &detail);
  ++sensor.sequence_number;
  if (reject != ros2::Ros2Reject::kNone) {
    Reject(sensor, ReasonOf(reject), detail);
    return;
  }
  Deliver(sensor, msg.header, msg.width, msg.height, std::move(xyz), received_at);
}

void Ros2Ingest::Deliver(SensorState& sensor, const ros2::Header& header, std::uint32_t width,
                         std::uint32_t height, std::vector<float> xyz,
                         std::chrono::steady_clock::time_point received_at) {
  // With tf the points move from the message's frame into the sensor's (the mount's inverse).
  const Eigen::Isometry3d T_sensor_frame = sensor.config.mount.inverse(Eigen::Isometry);
  const bool move = options_.tf && !sensor.config.mount.isApprox(Eigen::Isometry3d::Identity());
  Cloud cloud = CloudFromRos2(sensor.config.sensor_id, sensor.sequence_number,
                              header.stamp.seconds(), Eigen::Isometry3d::Identity(),
                              move ? &T_sensor_frame : nullptr, width, height, std::move(xyz));
  cloud.received_at = received_at;
  Place(sensor, std::move(cloud), Ros2FrameId(header.frame_id));
}

void Ros2Ingest::OnImage(SensorState& sensor, const sensor_msgs_msg_dds__Image_& sample) {
  const auto received_at = std::chrono::steady_clock::now();
  ++sensor.sequence_number;
  if (!sensor.config.pinhole) {
    Reject(sensor, RejectReason::kNoCameraInfo, sensor.no_camera_info);
    return;
  }
  if (!sensor.camera_info_mismatch.empty()) {
    Reject(sensor, RejectReason::kCameraInfoMismatch, sensor.camera_info_mismatch);
    return;
  }
  const ros2::Image image = Ros2FromDds(sample);
  // The sensor's intrinsics (configured, or its first CameraInfo's) are the camera's: its beam
  // grid is built from them; every CameraInfo is checked against them.
  const PinholeIntrinsics& k = *sensor.config.pinhole;
  ros2::CameraInfo info;
  info.width = static_cast<std::uint32_t>(k.width_px);
  info.height = static_cast<std::uint32_t>(k.height_px);
  info.k = {k.fx_px, 0.0, k.cx_px, 0.0, k.fy_px, k.cy_px, 0.0, 0.0, 1.0};
  std::vector<float> xyz;
  std::string detail;
  const auto reject =
      ros2::PointsFromDepthImage(image, info, k.stride, options_.limits.max_points, &xyz, &detail);
  if (reject != ros2::Ros2Reject::kNone) {
    Reject(sensor, ReasonOf(reject), detail);
    return;
  }
  Deliver(sensor, image.header, ros2::StridedSize(image.width, k.stride),
          ros2::StridedSize(image.height, k.stride), std::move(xyz), received_at);
}

TransformStatus Ros2Ingest::PoseOf(const std::string& frame_id, double stamp_s,
                                   Eigen::Isometry3d* T_map_frame) const {
  return tf_.Lookup(options_.map_frame, frame_id, stamp_s, T_map_frame);
}

void Ros2Ingest::Place(SensorState& sensor, Cloud cloud, const std::string& frame_id) {
  if (!options_.tf) {
    Queue(sensor, std::move(cloud), Eigen::Isometry3d::Identity());  // the mount is the pose
    return;
  }
  if (frame_id.empty()) {
    Reject(sensor, RejectReason::kNoTransform, "header.frame_id is empty");
    return;
  }
  if (sensor.parked.empty()) {  // else behind the parked ones, in order
    Eigen::Isometry3d T_map_frame;
    const TransformStatus status = PoseOf(frame_id, cloud.stamp_s, &T_map_frame);
    if (status == TransformStatus::kOk) {
      Queue(sensor, std::move(cloud), T_map_frame);
      return;
    }
    if (status == TransformStatus::kTooOld || options_.tf_wait_s <= 0.0) {
      Reject(sensor, ReasonOf(status),
             fmt::format("{} from '{}' to '{}' at {:.6f} s", TransformStatusName(status),
                         LoggableText(frame_id), LoggableText(options_.map_frame), cloud.stamp_s));
      return;
    }
  }
  const auto wait = std::chrono::duration_cast<std::chrono::steady_clock::duration>(
      std::chrono::duration<double>(options_.tf_wait_s));
  sensor.parked.push_back({std::move(cloud), frame_id, std::chrono::steady_clock::now() + wait});
  if (sensor.parked.size() > Ros2IngestOptions::kMaxParkedPerSensor) RetryParked(false);
}

void Ros2Ingest::RetryParked(bool give_up_all) {
  const auto now = std::chrono::steady_clock::now();
  for (SensorState& sensor : sensors_) {
    while (!sensor.parked.empty()) {
      Parked& p = sensor.parked.front();
      Eigen::Isometry3d T_map_frame;
      const TransformStatus status = PoseOf(p.frame_id, p.cloud.stamp_s, &T_map_frame);
      const bool crowded = sensor.parked.size() > Ros2IngestOptions::kMaxParkedPerSensor;
      if (status == TransformStatus::kOk) {
        Queue(sensor, std::move(p.cloud), T_map_frame);
      } else if (give_up_all || crowded || status == TransformStatus::kTooOld ||
                 now >= p.deadline) {
        Reject(sensor, ReasonOf(status),
               fmt::format("{} from '{}' to '{}' at {:.6f} s (waited up to {} s)",
                           TransformStatusName(status), LoggableText(p.frame_id),
                           LoggableText(options_.map_frame), p.cloud.stamp_s, options_.tf_wait_s));
      } else {
        break;  // the oldest still waits, and the younger ones behind it
      }
      sensor.parked.pop_front();
    }
  }
}

void Ros2Ingest::Queue(SensorState& sensor, Cloud cloud, const Eigen::Isometry3d& T_map_frame) {
  cloud.T_world_published = T_map_frame;
  std::string detail;
  const auto reason = ValidateCloud(
      cloud, options_.limits, [this](const std::string& id) { return queues_->Known(id); },
      &detail);
  if (reason) {
    Reject(sensor, *reason, detail);
    return;
  }
  // A reliable sensor waits for room (lossless); sensor data replaces the oldest cloud.
  (void)queues_->Push(std::move(cloud), sensor.config.reliable ? &stop_ : nullptr);
}

void Ros2Ingest::Reject(const SensorState& sensor, RejectReason reason, const std::string& detail) {
  queues_->CountRejected(sensor.config.sensor_id, reason);
  log_.Log(reason, sensor.config.sensor_id, detail);
}

}  // namespace fusion::service
