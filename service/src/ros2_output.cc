#include "fusion/service/ros2_output.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <exception>
#include <sstream>

#include "fusion/service/persistence.h"
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

std::string OctomapBinaryData(const octomap::OcTree& tree, const StateThresholds& t) {
  std::size_t nodes = 0;
  return MaximumLikelihoodData(tree, t, &nodes);
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

Status Ros2Output::CreateWriter(dds_entity_t participant, Topic* t) {
  const dds_topic_descriptor_t* type = t->content == Content::kCentres
                                           ? &sensor_msgs_msg_dds__PointCloud2__desc
                                           : &octomap_msgs_msg_dds__Octomap__desc;
  const dds_entity_t topic = dds_create_topic(participant, type, t->name, nullptr, nullptr);
  if (topic < 0) return Status::Error(DdsError("dds_create_topic", t->name, topic));
  // octomap_server's latched map topics: a subscriber that joins late still gets the last map.
  dds_qos_t* qos = dds_create_qos();
  dds_qset_reliability(qos, DDS_RELIABILITY_RELIABLE, DDS_MSECS(options_.write_timeout.count()));
  dds_qset_durability(qos, DDS_DURABILITY_TRANSIENT_LOCAL);
  dds_qset_history(qos, DDS_HISTORY_KEEP_LAST, 1);
  t->writer = dds_create_writer(participant, topic, qos, nullptr);
  dds_delete_qos(qos);
  if (t->writer < 0) {
    const dds_return_t rc = t->writer;
    t->writer = 0;
    return Status::Error(DdsError("dds_create_writer", t->name, rc));
  }
  return Status::Ok();
}

Status Ros2Output::Start(dds_entity_t participant) {
  if (!options_.enabled()) return Status::Ok();
  const bool wanted[] = {options_.binary, options_.full, options_.point_cloud_centers};
  std::string names;
  for (std::size_t i = 0; i < std::size(topics_); ++i) {
    if (!wanted[i]) continue;
    if (Status s = CreateWriter(participant, &topics_[i]); !s.ok()) return s;
    names += std::string(" ") + topics_[i].name;
  }
  spdlog::info("ROS 2 output: the map in frame '{}' at most {} Hz on{}", options_.map_frame,
               options_.rate_hz, names);
  thread_ = std::thread([this] { Loop(); });
  return Status::Ok();
}

std::vector<Ros2TopicStats> Ros2Output::TopicStats() const {
  std::vector<Ros2TopicStats> stats;
  for (const Topic& t : topics_) {
    if (t.writer == 0) continue;
    Ros2TopicStats s;
    s.topic = t.name;
    s.publications = t.publications.load();
    s.bytes = t.bytes.load();
    s.failures = t.failures.load();
    dds_publication_matched_status_t matched{};
    if (dds_get_publication_matched_status(t.writer, &matched) == DDS_RETCODE_OK) {
      s.matched_subscribers = matched.current_count;
    }
    stats.push_back(std::move(s));
  }
  return stats;
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
      Publish(*snapshot);
      last_version_ = snapshot->version;  // a failed version is not retried: the next one comes
    }
    next += period;
    // Serialising took longer than a period: start the next one a period from now.
    next = std::max(next, std::chrono::steady_clock::now());
    lock.lock();
  }
}

void Ros2Output::Publish(const MapSnapshot& snapshot) {
  const auto start = std::chrono::steady_clock::now();
  for (Topic& topic : topics_) {
    if (topic.writer == 0) continue;
    std::size_t bytes = 0;
    Status published;
    try {
      published = PublishOn(topic, *snapshot.tree, &bytes);
    } catch (const std::exception& e) {  // e.g. bad_alloc serialising a huge map
      published = Status::Error(std::string(topic.name) + ": serialising the map: " + e.what());
    }
    if (!published.ok()) {
      CountFailure(topic, published);
      continue;
    }
    topic.publications.fetch_add(1);
    topic.bytes.fetch_add(bytes);
  }
  spdlog::debug(
      "ROS 2 output: map version {} published ({:.1f} ms)", snapshot.version,
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count());
}

Status Ros2Output::PublishOn(const Topic& topic, const octomap::OcTree& tree, std::size_t* bytes) {
  // A DDS sequence holds at most 2^32 - 1 bytes.
  constexpr std::size_t kMaxBytes = UINT32_MAX;
  const auto too_large = [&](std::size_t n) {
    return Status::Error(std::string(topic.name) + ": the map is " + std::to_string(n) +
                         " bytes, more than a message holds");
  };
  dds_return_t rc = DDS_RETCODE_OK;
  if (topic.content == Content::kCentres) {
    std::vector<float> xyz = OccupiedLeafCentres(tree);
    *bytes = xyz.size() * sizeof(float);
    if (*bytes > kMaxBytes) return too_large(*bytes);
    rc = WriteCentres(topic.writer, options_.map_frame, xyz);
  } else {
    const bool binary = topic.content == Content::kBinary;
    std::string data = binary ? OctomapBinaryData(tree, options_.thresholds) : OctomapFullData(tree);
    *bytes = data.size();
    if (*bytes > kMaxBytes) return too_large(*bytes);
    rc = WriteOctomap(topic.writer, options_.map_frame, binary, tree, data);
  }
  if (rc != DDS_RETCODE_OK) return Status::Error(DdsError("dds_write", topic.name, rc));
  return Status::Ok();
}

void Ros2Output::CountFailure(Topic& topic, const Status& status) {
  topic.failures.fetch_add(1);
  ++unlogged_failures_;
  const auto now = std::chrono::steady_clock::now();
  if (now - last_failure_log_ < options_.log_interval) return;
  spdlog::warn("ROS 2 output: {} publication(s) failed, the last: {}", unlogged_failures_,
               status.message());
  unlogged_failures_ = 0;
  last_failure_log_ = now;
}

}  // namespace fusion::service
