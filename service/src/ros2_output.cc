#include "fusion/service/ros2_output.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <exception>
#include <sstream>

#include "fusion/service/ros2_ingest.h"
#include "octomap_msgs.h"
#include "sensor_msgs.h"

namespace fusion::service {
namespace {

constexpr std::uint8_t kPointFieldFloat32 = 7;  // sensor_msgs/PointField FLOAT32

std::string DdsError(const char* call, const char* topic, dds_return_t rc) {
  return std::string(call) + " '" + topic + "': " + dds_strretcode(rc);
}

// header.stamp: the time of the publication, as octomap_server's service replies stamp theirs.
builtin_interfaces_msg_dds__Time_ StampNow() {
  const auto since_epoch = std::chrono::system_clock::now().time_since_epoch();
  const auto s = std::chrono::duration_cast<std::chrono::seconds>(since_epoch);
  const auto ns = std::chrono::duration_cast<std::chrono::nanoseconds>(since_epoch - s);
  return {static_cast<std::int32_t>(s.count()), static_cast<std::uint32_t>(ns.count())};
}

std_msgs_msg_dds__Header_ HeaderOf(const std::string& frame_id) {
  // The writers only read the sample: the const_casts lend it our strings without a copy.
  return {StampNow(), const_cast<char*>(frame_id.c_str())};
}

dds_return_t WriteOctomap(dds_entity_t writer, const std::string& frame_id, bool binary,
                          const octomap::OcTree& tree, std::string& data) {
  const std::string id = tree.getTreeType();
  octomap_msgs_msg_dds__Octomap_ msg{};
  msg.header = HeaderOf(frame_id);
  msg.binary = binary;
  msg.id = const_cast<char*>(id.c_str());
  msg.resolution = tree.getResolution();
  msg.data._length = msg.data._maximum = static_cast<std::uint32_t>(data.size());
  msg.data._buffer = reinterpret_cast<std::int8_t*>(data.data());
  msg.data._release = false;
  return dds_write(writer, &msg);
}

// A PointCloud2 of one row, fields x y z FLOAT32 at offsets 0, 4, 8, in the host's byte order.
dds_return_t WriteCentres(dds_entity_t writer, const std::string& frame_id,
                          std::vector<float>& xyz) {
  static const char* const kNames[] = {"x", "y", "z"};
  sensor_msgs_msg_dds__PointField_ fields[3];
  for (std::uint32_t i = 0; i < 3; ++i) {
    fields[i] = {const_cast<char*>(kNames[i]), 4 * i, kPointFieldFloat32, 1};
  }
  sensor_msgs_msg_dds__PointCloud2_ msg{};
  msg.header = HeaderOf(frame_id);
  msg.height = 1;
  msg.width = static_cast<std::uint32_t>(xyz.size() / 3);
  msg.fields = {3, 3, fields, false};
  msg.is_bigendian = __BYTE_ORDER__ == __ORDER_BIG_ENDIAN__;
  msg.point_step = 3 * sizeof(float);
  msg.row_step = msg.point_step * msg.width;
  msg.data._length = msg.data._maximum = static_cast<std::uint32_t>(xyz.size() * sizeof(float));
  msg.data._buffer = reinterpret_cast<std::uint8_t*>(xyz.data());
  msg.data._release = false;
  msg.is_dense = true;
  return dds_write(writer, &msg);
}

}  // namespace

StatusOr<Ros2OutputOptions> Ros2OutputOptionsFromConfig(const fusion::v1::ServiceConfig& config) {
  const auto ingest = Ros2IngestOptionsFromConfig(config);  // the one reading of map_frame
  if (!ingest.ok()) return ingest.status();
  const auto& r = config.ros2();
  Ros2OutputOptions options;
  options.rate_hz = r.octomap_rate_hz();
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

std::string OctomapBinaryData(const octomap::OcTree& tree) {
  std::ostringstream out(std::ios::binary);
  tree.writeBinaryData(out);
  return out.str();
}

std::string OctomapFullData(const octomap::OcTree& tree) {
  std::ostringstream out(std::ios::binary);
  tree.writeData(out);
  return out.str();
}

std::vector<float> OccupiedLeafCentres(const octomap::OcTree& tree) {
  std::vector<float> xyz;
  for (auto it = tree.begin_leafs(), end = tree.end_leafs(); it != end; ++it) {
    if (!tree.isNodeOccupied(*it)) continue;
    const octomap::point3d c = it.getCoordinate();
    xyz.insert(xyz.end(), {c.x(), c.y(), c.z()});
  }
  return xyz;
}

Ros2Output::Ros2Output(const SnapshotHub* hub, Ros2OutputOptions options)
    : hub_(hub), options_(std::move(options)) {}

Ros2Output::~Ros2Output() { Stop(); }

Status Ros2Output::CreateWriter(dds_entity_t participant, const dds_topic_descriptor_t* type,
                                const char* topic_name, dds_entity_t* writer) {
  const dds_entity_t topic = dds_create_topic(participant, type, topic_name, nullptr, nullptr);
  if (topic < 0) return Status::Error(DdsError("dds_create_topic", topic_name, topic));
  // octomap_server's latched map topics: a subscriber that joins late still gets the last map.
  dds_qos_t* qos = dds_create_qos();
  dds_qset_reliability(qos, DDS_RELIABILITY_RELIABLE, DDS_MSECS(options_.write_timeout.count()));
  dds_qset_durability(qos, DDS_DURABILITY_TRANSIENT_LOCAL);
  dds_qset_history(qos, DDS_HISTORY_KEEP_LAST, 1);
  *writer = dds_create_writer(participant, topic, qos, nullptr);
  dds_delete_qos(qos);
  if (*writer < 0) return Status::Error(DdsError("dds_create_writer", topic_name, *writer));
  return Status::Ok();
}

Status Ros2Output::Start(dds_entity_t participant) {
  if (!options_.enabled()) return Status::Ok();
  struct Wanted {
    bool on;
    const char* topic;
    const dds_topic_descriptor_t* type;
    dds_entity_t* writer;
  };
  const Wanted wanted[] = {
      {options_.binary, kOctomapBinaryTopic, &octomap_msgs_msg_dds__Octomap__desc,
       &writers_.binary},
      {options_.full, kOctomapFullTopic, &octomap_msgs_msg_dds__Octomap__desc, &writers_.full},
      {options_.point_cloud_centers, kOctomapCentersTopic, &sensor_msgs_msg_dds__PointCloud2__desc,
       &writers_.centres}};
  for (const Wanted& w : wanted) {
    if (!w.on) continue;
    if (Status s = CreateWriter(participant, w.type, w.topic, w.writer); !s.ok()) return s;
  }
  spdlog::info("ROS 2 output: the map in frame '{}' at most {} Hz on{}{}{}", options_.map_frame,
               options_.rate_hz, writers_.binary ? std::string(" ") + kOctomapBinaryTopic : "",
               writers_.full ? std::string(" ") + kOctomapFullTopic : "",
               writers_.centres ? std::string(" ") + kOctomapCentersTopic : "");
  thread_ = std::thread([this] { Loop(); });
  return Status::Ok();
}

void Ros2Output::Stop() {
  {
    std::lock_guard<std::mutex> lock(stop_mutex_);
    stop_ = true;
  }
  stop_cv_.notify_all();
  if (thread_.joinable()) thread_.join();
}

void Ros2Output::Loop() {
  const auto period = std::chrono::duration_cast<std::chrono::steady_clock::duration>(
      std::chrono::duration<double>(1.0 / options_.rate_hz));
  auto next = std::chrono::steady_clock::now();
  std::unique_lock<std::mutex> lock(stop_mutex_);
  while (!stop_cv_.wait_until(lock, next, [this] { return stop_; })) {
    lock.unlock();
    // A reference to the immutable version: the worker publishes the next one meanwhile.
    const auto snapshot = hub_->Current();
    if (snapshot->version != last_version_) {
      Status published;
      try {
        published = Publish(*snapshot);
      } catch (const std::exception& e) {  // e.g. bad_alloc serialising a huge map
        published = Status::Error(std::string("serialising the map: ") + e.what());
      }
      if (published.ok()) {
        published_.fetch_add(1);
      } else {
        CountFailure(published);
      }
      last_version_ = snapshot->version;  // a failed version is not retried: the next one comes
    }
    next += period;
    // Serialising took longer than a period: start the next one a period from now.
    next = std::max(next, std::chrono::steady_clock::now());
    lock.lock();
  }
}

Status Ros2Output::Publish(const MapSnapshot& snapshot) {
  const octomap::OcTree& tree = *snapshot.tree;
  const auto start = std::chrono::steady_clock::now();
  // A DDS sequence holds at most 2^32 - 1 bytes.
  constexpr std::size_t kMaxBytes = UINT32_MAX;
  const auto too_large = [](const char* topic, std::size_t bytes) {
    return Status::Error(std::string(topic) + ": the map is " + std::to_string(bytes) +
                         " bytes, more than a message holds");
  };
  if (writers_.binary) {
    std::string data = OctomapBinaryData(tree);
    if (data.size() > kMaxBytes) return too_large(kOctomapBinaryTopic, data.size());
    const dds_return_t rc = WriteOctomap(writers_.binary, options_.map_frame, true, tree, data);
    if (rc != DDS_RETCODE_OK) return Status::Error(DdsError("dds_write", kOctomapBinaryTopic, rc));
  }
  if (writers_.full) {
    std::string data = OctomapFullData(tree);
    if (data.size() > kMaxBytes) return too_large(kOctomapFullTopic, data.size());
    const dds_return_t rc = WriteOctomap(writers_.full, options_.map_frame, false, tree, data);
    if (rc != DDS_RETCODE_OK) return Status::Error(DdsError("dds_write", kOctomapFullTopic, rc));
  }
  if (writers_.centres) {
    std::vector<float> xyz = OccupiedLeafCentres(tree);
    if (xyz.size() * sizeof(float) > kMaxBytes) {
      return too_large(kOctomapCentersTopic, xyz.size() * sizeof(float));
    }
    const dds_return_t rc = WriteCentres(writers_.centres, options_.map_frame, xyz);
    if (rc != DDS_RETCODE_OK) return Status::Error(DdsError("dds_write", kOctomapCentersTopic, rc));
  }
  spdlog::debug(
      "ROS 2 output: map version {} published ({:.1f} ms)", snapshot.version,
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count());
  return Status::Ok();
}

void Ros2Output::CountFailure(const Status& status) {
  failures_.fetch_add(1);
  ++unlogged_failures_;
  const auto now = std::chrono::steady_clock::now();
  if (now - last_failure_log_ < options_.log_interval) return;
  spdlog::warn("ROS 2 output: {} publication(s) failed, the last: {}", unlogged_failures_,
               status.message());
  unlogged_failures_ = 0;
  last_failure_log_ = now;
}

}  // namespace fusion::service
