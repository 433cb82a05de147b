// The scene every rosbag2 test records: a robot driving and turning in "odom" (tf on /tf, 10 Hz,
// 0..2.9 s), "odom" fixed in "map" and the sensors mounted on "base_link" (/tf_static); a
// lidar whose PointCloud2 (8 x 6, organized, in its optical frame) sees a board 2 m ahead, and
// a depth camera (16UC1 8 x 6 with CameraInfo). Written as sqlite3 (.db3 + metadata.yaml) and
// as MCAP (one uncompressed, one zstd and one lz4 chunk, a message outside any chunk, an
// attachment and metadata) holding the same messages in the same order.
#pragma once

#include <Eigen/Geometry>
#include <cmath>
#include <string>
#include <vector>

#include "../../support/mcap_writer.h"
#include "../../support/rosbag2_sqlite_writer.h"
#include "fusion/ros2/cdr.h"

namespace fusion::test {

inline constexpr std::int32_t kEpochS = 1700000000;
inline constexpr const char* kPointsTopic = "/lidar/points";
inline constexpr const char* kDepthTopic = "/camera/depth/image_raw";
inline constexpr const char* kInfoTopic = "/camera/depth/camera_info";

struct BagEvent {
  std::string topic, type;
  std::int64_t log_time_ns;
  std::vector<std::uint8_t> data;
  double t_s;  // scene time (stamp - kEpochS)
};

inline ros2::Time StampAt(double t_s) {
  const auto ns = static_cast<std::int64_t>(std::llround(t_s * 1e9));
  return {kEpochS + static_cast<std::int32_t>(ns / 1000000000),
          static_cast<std::uint32_t>(ns % 1000000000)};
}
inline std::int64_t LogTimeNs(double t_s) {
  return std::int64_t{kEpochS} * 1000000000 + std::llround(t_s * 1e9);
}

// The robot in odom at t: 0.5 m/s along x, 0.1 m/s along y, turning at 0.2 rad/s.
inline Eigen::Isometry3d T_odom_base(double t_s) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.translation() = Eigen::Vector3d(0.5 * t_s, 0.1 * t_s, 0.0);
  T.linear() = Eigen::AngleAxisd(0.2 * t_s, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  return T;
}
inline Eigen::Isometry3d T_map_odom() {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.translation() = Eigen::Vector3d(1.0, -2.0, 0.0);
  return T;
}
// An optical frame (x right, y down, z forward) on base_link (x forward, z up) at `t`.
inline Eigen::Isometry3d OpticalMount(const Eigen::Vector3d& t) {
  Eigen::Matrix3d R;
  R << 0, 0, 1, -1, 0, 0, 0, -1, 0;
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = R;
  T.translation() = t;
  return T;
}
inline Eigen::Isometry3d T_base_lidar() { return OpticalMount({0.2, 0.0, 0.5}); }
inline Eigen::Isometry3d T_base_camera() { return OpticalMount({0.1, 0.05, 0.4}); }

inline ros2::TransformStamped Tf(const std::string& parent, const std::string& child, double t_s,
                                 const Eigen::Isometry3d& T) {
  ros2::TransformStamped m;
  m.header = {StampAt(t_s), parent};
  m.child_frame_id = child;
  const Eigen::Quaterniond q(T.rotation());
  m.transform.translation = {T.translation().x(), T.translation().y(), T.translation().z()};
  m.transform.rotation = {q.x(), q.y(), q.z(), q.w()};
  return m;
}

// Lidar point (i, j) of the 8 x 6 grid on the board (z = 2 m); (3, 2) is no return.
inline Eigen::Vector3f BoardPoint(int i, int j) {
  if (i == 3 && j == 2) return Eigen::Vector3f::Constant(NAN);
  return {-0.35f + 0.1f * i, -0.25f + 0.1f * j, 2.0f};
}

inline std::vector<std::uint8_t> CloudAt(double t_s, bool big_endian) {
  std::vector<std::uint8_t> data(8 * 6 * 16);
  for (int j = 0; j < 6; ++j) {
    for (int i = 0; i < 8; ++i) {
      const Eigen::Vector3f p = BoardPoint(i, j);
      const float values[4] = {p.x(), p.y(), p.z(), 100.0f};
      for (int f = 0; f < 4; ++f) {
        std::uint8_t* out = &data[(j * 8 + i) * 16 + 4 * f];
        std::memcpy(out, &values[f], 4);
        if (big_endian) std::swap(out[0], out[3]), std::swap(out[1], out[2]);
      }
    }
  }
  ros2::PointCloud2 m;
  m.header = {StampAt(t_s), "lidar"};
  m.height = 6, m.width = 8;
  m.fields = {{"x", 0, ros2::PointField::FLOAT32, 1},
              {"y", 4, ros2::PointField::FLOAT32, 1},
              {"z", 8, ros2::PointField::FLOAT32, 1},
              {"intensity", 12, ros2::PointField::FLOAT32, 1}};
  m.is_bigendian = big_endian;
  m.point_step = 16, m.row_step = 128;
  m.data = ros2::ByteView(data);
  m.is_dense = false;
  return ros2::EncodeCdr(m, big_endian ? ros2::CdrEndian::kBig : ros2::CdrEndian::kLittle);
}

inline constexpr double kFx = 4.0, kCx = 3.5, kFy = 4.0, kCy = 2.5;

inline std::vector<std::uint8_t> DepthAt(double t_s) {
  std::vector<std::uint8_t> data(8 * 6 * 2);
  for (std::size_t i = 0; i < 48; ++i) {
    const std::uint16_t mm = i == 0 ? 0 : 2000;  // pixel (0, 0): no return
    std::memcpy(&data[2 * i], &mm, 2);
  }
  ros2::Image m;
  m.header = {StampAt(t_s), "camera_optical"};
  m.height = 6, m.width = 8, m.encoding = "16UC1", m.step = 16;
  m.data = ros2::ByteView(data);
  return ros2::EncodeCdr(m);
}

inline std::vector<std::uint8_t> CameraInfoAt(double t_s) {
  ros2::CameraInfo m;
  m.header = {StampAt(t_s), "camera_optical"};
  m.height = 6, m.width = 8, m.distortion_model = "plumb_bob", m.d = {0, 0, 0, 0, 0};
  m.k = {kFx, 0, kCx, 0, kFy, kCy, 0, 0, 1};
  m.r = {1, 0, 0, 0, 1, 0, 0, 0, 1};
  m.p = {kFx, 0, kCx, 0, 0, kFy, kCy, 0, 0, 0, 1, 0};
  return ros2::EncodeCdr(m);
}

// Stamps (scene seconds) of the lidar clouds that have a pose, and the one past the last tf.
inline const std::vector<double> kCloudTimes = {0.15, 0.55, 1.15, 1.55, 2.15, 2.55};
inline constexpr double kCloudAfterTf = 2.95;
inline const std::vector<double> kDepthTimes = {0.35, 1.35, 2.35};

// Every message of the bag in log-time order.
inline std::vector<BagEvent> SceneEvents() {
  std::vector<BagEvent> events;
  auto add = [&](const std::string& topic, const std::string& type, double log_t,
                 std::vector<std::uint8_t> data, double t) {
    events.push_back({topic, type, LogTimeNs(log_t), std::move(data), t});
  };
  const char* kTf = "tf2_msgs/msg/TFMessage";
  ros2::TFMessage statics;
  statics.transforms = {Tf("map", "odom", 0, T_map_odom()),
                        Tf("base_link", "lidar", 0, T_base_lidar()),
                        Tf("base_link", "camera_optical", 0, T_base_camera())};
  add("/tf_static", kTf, 0.0, ros2::EncodeCdr(statics), 0.0);
  for (int k = 0; k < 30; ++k) {
    const double t = 0.1 * k;
    ros2::TFMessage tf;
    tf.transforms = {Tf("odom", "base_link", t, T_odom_base(t))};
    add("/tf", kTf, t + 0.001, ros2::EncodeCdr(tf), t);
  }
  for (std::size_t k = 0; k < kCloudTimes.size(); ++k) {
    add(kPointsTopic, "sensor_msgs/msg/PointCloud2", kCloudTimes[k] + 0.02,
        CloudAt(kCloudTimes[k], k == 3), kCloudTimes[k]);
  }
  add(kPointsTopic, "sensor_msgs/msg/PointCloud2", kCloudAfterTf + 0.02,
      CloudAt(kCloudAfterTf, false), kCloudAfterTf);
  for (const double t : kDepthTimes) {
    add(kInfoTopic, "sensor_msgs/msg/CameraInfo", t + 0.01, CameraInfoAt(t), t);
    add(kDepthTopic, "sensor_msgs/msg/Image", t + 0.015, DepthAt(t), t);
  }
  add("/chatter", "std_msgs/msg/String", 1.0, {0, 1, 0, 0, 3, 0, 0, 0, 'h', 'i', 0}, 1.0);
  std::stable_sort(events.begin(), events.end(), [](const BagEvent& a, const BagEvent& b) {
    return a.log_time_ns < b.log_time_ns;
  });
  return events;
}

// The topics in order of first appearance.
inline std::vector<std::pair<std::string, std::string>> SceneTopics(
    const std::vector<BagEvent>& events) {
  std::vector<std::pair<std::string, std::string>> topics;
  for (const auto& e : events) {
    bool known = false;
    for (const auto& t : topics) known = known || t.first == e.topic;
    if (!known) topics.emplace_back(e.topic, e.type);
  }
  return topics;
}

// directory/scene.db3 and directory/metadata.yaml.
inline void WriteSqliteBag(const std::string& directory, const std::vector<BagEvent>& events) {
  {
    Rosbag2SqliteWriter writer(directory + "/scene.db3");
    std::map<std::string, int> ids;
    for (const auto& [name, type] : SceneTopics(events)) ids[name] = writer.AddTopic(name, type);
    for (const auto& e : events) writer.AddMessage(ids[e.topic], e.log_time_ns, e.data);
  }
  WriteRosbag2Metadata(directory, "sqlite3", {"scene.db3"});
}

// The MCAP file's bytes; *chunks (if given) the top-level records of the three chunks.
inline std::string SceneMcap(const std::vector<BagEvent>& events,
                             std::vector<McapWriter::RecordStart>* chunks = nullptr,
                             std::size_t* chunk_records = nullptr) {
  McapWriter writer;
  std::map<std::string, std::uint16_t> channels;
  for (const auto& [name, type] : SceneTopics(events)) {
    channels[name] = writer.AddChannel(writer.AddSchema(type), name);
  }
  const char* const kCompression[3] = {"", "zstd", "lz4"};
  int chunk = -1;
  for (const auto& e : events) {
    const int due = std::min(2, static_cast<int>(e.t_s));  // [0, 1), [1, 2), [2, ...)
    if (e.topic == "/chatter") {  // a message outside any chunk, between the first two
      if (chunk >= 0) writer.EndChunk();
      chunk = -2;
      writer.AddMessage(channels[e.topic], static_cast<std::uint64_t>(e.log_time_ns), e.data);
      continue;
    }
    if (due != chunk) {
      if (chunk >= 0) writer.EndChunk();
      chunk = due;
      writer.BeginChunk(kCompression[chunk]);
    }
    writer.AddMessage(channels[e.topic], static_cast<std::uint64_t>(e.log_time_ns), e.data);
  }
  writer.EndChunk();
  writer.AddAttachment("calibration.yaml", "fx: 4\n");
  writer.AddMetadata("rosbag2", "ros_distro", "humble");
  std::string bytes = writer.Finish();
  if (chunks != nullptr) {
    chunks->clear();
    for (std::size_t i = 0; i < writer.records().size(); ++i) {
      if (writer.records()[i].opcode == 0x06) {
        chunks->push_back(writer.records()[i]);
        if (chunk_records != nullptr) chunk_records[chunks->size() - 1] = i;
      }
    }
  }
  return bytes;
}

}  // namespace fusion::test
