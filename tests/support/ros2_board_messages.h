// Test helper: the board scene of the paper as ROS 2 messages (Fast DDS types from idl/ros2/):
// simulated SR-3000 PointCloud2s, depth images of the board plane with their CameraInfo, tf
// messages, and the configuration blocks of the sensors that see them.
#pragma once

#include <Eigen/Geometry>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <sstream>
#include <string>
#include <vector>

#include "fastdds_ros2.h"
#include "fusion/core/sensor.h"
#include "fusion/sim/scene.h"
#include "fusion/sim/simulator.h"

namespace fusion::testing::ros2_board {

namespace sm = sensor_msgs::msg::dds_;
namespace gm = geometry_msgs::msg::dds_;
using TfMessage = tf2_msgs::msg::dds_::TFMessage_;

constexpr int kCols = 44;  // SR-3000 field of view with a quarter of its beams
constexpr int kRows = 36;
// The paper's board (x = 1.75), a point in front of it and two where a cloud posed 0.4 m too
// near or too far would put it.
inline const Eigen::Vector3d kOnBoard(1.75, 0.0, 0.2);
inline const Eigen::Vector3d kInFront(1.0, 0.0, 0.2);
inline const Eigen::Vector3d kTooNear(1.35, 0.0, 0.2);
inline const Eigen::Vector3d kTooFar(2.15, 0.0, 0.2);
// A small depth camera (80 x 60) looking at the board from the origin: depth 1.75 m everywhere.
constexpr double kFocalPx = 60.0, kCxPx = 39.5, kCyPx = 29.5;
constexpr int kImageWidth = 80, kImageHeight = 60;

// The rotation of an optical frame (x right, y down, z forward) looking along the map's +x.
inline Eigen::Isometry3d OpticalAxes() {
  return fusion::sim::ForwardLookingPose(Eigen::Vector3d::Zero());
}

inline Eigen::Isometry3d Translation(double x, double y, double z) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.translation() = Eigen::Vector3d(x, y, z);
  return T;
}

inline TfMessage Tf(const std::string& parent, const std::string& child, double stamp_s,
                    const Eigen::Isometry3d& T_parent_child) {
  gm::TransformStamped_ t;
  t.header().frame_id(parent);
  t.header().stamp(Ros2Time(stamp_s));
  t.child_frame_id(child);
  const Eigen::Quaterniond q(T_parent_child.rotation());
  t.transform().translation().x(T_parent_child.translation().x());
  t.transform().translation().y(T_parent_child.translation().y());
  t.transform().translation().z(T_parent_child.translation().z());
  t.transform().rotation().x(q.x());
  t.transform().rotation().y(q.y());
  t.transform().rotation().z(q.z());
  t.transform().rotation().w(q.w());
  TfMessage message;
  message.transforms().push_back(t);
  return message;
}

inline sm::PointField_ Field(const std::string& name, std::uint32_t offset, std::uint8_t datatype) {
  sm::PointField_ f;
  f.name(name);
  f.offset(offset);
  f.datatype(datatype);
  f.count(1);
  return f;
}

// One simulated SR-3000 frame of the board from the origin as a PointCloud2 (x y z intensity,
// 16 bytes a point; no return = NaN) in `frame_id`.
inline sm::PointCloud2_ BoardCloud(std::uint64_t seed, const std::string& frame_id,
                                   double stamp_s) {
  auto spec = fusion::sim::WithTessellation(*fusion::SensorPreset("sr3000"), kCols, kRows);
  fusion::sim::RangeSimulator simulator(fusion::sim::PaperBoardScene(), spec);
  simulator.Reseed(seed);
  const auto frame = simulator.Capture(OpticalAxes());
  sm::PointCloud2_ m;
  m.header().frame_id(frame_id);
  m.header().stamp(Ros2Time(stamp_s));
  m.height(static_cast<std::uint32_t>(frame.rows));
  m.width(static_cast<std::uint32_t>(frame.cols));
  for (auto [name, offset] : {std::pair{"x", 0u}, {"y", 4u}, {"z", 8u}, {"intensity", 12u}}) {
    m.fields().push_back(Field(name, offset, 7));
  }
  m.is_bigendian(false);
  m.point_step(16);
  m.row_step(16 * m.width());
  m.data().resize(std::size_t{m.row_step()} * m.height());
  for (std::size_t i = 0; i < frame.size(); ++i) {
    float point[4] = {frame.xyz[3 * i], frame.xyz[3 * i + 1], frame.xyz[3 * i + 2], 1.0f};
    if (frame.beyond_range[i]) {
      point[0] = point[1] = point[2] = std::numeric_limits<float>::quiet_NaN();
    }
    std::memcpy(m.data().data() + 16 * i, point, sizeof point);
  }
  m.is_dense(false);
  return m;
}

// A depth image of the board plane (1.75 m at every pixel) in `encoding` (16UC1 mm, 32FC1 m).
inline sm::Image_ BoardDepthImage(const std::string& encoding, const std::string& frame_id,
                                  double stamp_s, int width = kImageWidth,
                                  int height = kImageHeight) {
  sm::Image_ m;
  m.header().frame_id(frame_id);
  m.header().stamp(Ros2Time(stamp_s));
  m.height(height);
  m.width(width);
  m.encoding(encoding);
  m.is_bigendian(0);
  const bool mm = encoding == "16UC1";
  m.step(width * (mm ? 2 : 4));
  m.data().resize(std::size_t{m.step()} * height);
  for (int i = 0; i < width * height; ++i) {
    if (mm) {
      const std::uint16_t depth_mm = 1750;
      std::memcpy(m.data().data() + 2 * i, &depth_mm, 2);
    } else {
      const float depth_m = 1.75f;
      std::memcpy(m.data().data() + 4 * i, &depth_m, 4);
    }
  }
  return m;
}

inline sm::CameraInfo_ CameraInfo(const std::string& frame_id, double fx_px) {
  sm::CameraInfo_ m;
  m.header().frame_id(frame_id);
  m.height(kImageHeight);
  m.width(kImageWidth);
  m.distortion_model("plumb_bob");
  m.d(std::vector<double>(5, 0.0));
  m.k({fx_px, 0, kCxPx, 0, kFocalPx, kCyPx, 0, 0, 1});
  m.r({1, 0, 0, 0, 1, 0, 0, 0, 1});
  m.p({fx_px, 0, kCxPx, 0, 0, kFocalPx, kCyPx, 0, 0, 0, 1, 0});
  return m;
}

inline std::string PinholeBlock() {
  std::ostringstream s;
  s << "pinhole { fx: " << kFocalPx << " fy: " << kFocalPx << " cx: " << kCxPx << " cy: " << kCyPx
    << " width: " << kImageWidth << " height: " << kImageHeight << " }";
  return s.str();
}

// mount { ... } of a pose.
inline std::string MountBlock(const Eigen::Isometry3d& T) {
  const Eigen::Quaterniond q(T.rotation());
  std::ostringstream s;
  s.precision(17);
  s << "mount { tx: " << T.translation().x() << " ty: " << T.translation().y()
    << " tz: " << T.translation().z() << " qx: " << q.x() << " qy: " << q.y() << " qz: " << q.z()
    << " qw: " << q.w() << " }";
  return s.str();
}

}  // namespace fusion::testing::ros2_board
