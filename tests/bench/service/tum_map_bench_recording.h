// tum_map_bench (tum_map_bench.cc): the imported recording's clouds, read back frame by frame
// for the in-process map and OctoMap.
#pragma once

#include <Eigen/Geometry>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <string>
#include <vector>

#include "fusion/v1/recording.pb.h"
#include "tum_map_bench_common.h"

namespace fusion::tum_map_bench {

// ---- the recording -------------------------------------------------------------------------

struct Frame {
  Eigen::Isometry3d T_world_sensor = Eigen::Isometry3d::Identity();
  std::vector<float> xyz;  // sensor frame, NaN = no return
  std::vector<std::uint8_t> beyond_range;
  std::uint32_t width = 0, height = 0;
};

inline Eigen::Isometry3d PoseOf(const v1::RecordedPose& p) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = Eigen::Quaterniond(p.qw(), p.qx(), p.qy(), p.qz()).normalized().toRotationMatrix();
  T.translation() = Eigen::Vector3d(p.tx(), p.ty(), p.tz());
  return T;
}

inline Frame FrameOf(const v1::RecordedCloud& cloud) {
  Frame frame;
  frame.T_world_sensor = PoseOf(cloud.t_world_sensor());
  frame.xyz.resize(cloud.xyz_f32le().size() / sizeof(float));
  std::memcpy(frame.xyz.data(), cloud.xyz_f32le().data(), frame.xyz.size() * sizeof(float));
  frame.beyond_range.assign(cloud.beyond_range().begin(), cloud.beyond_range().end());
  frame.width = cloud.width();
  frame.height = cloud.height();
  return frame;
}

// The clouds of a .frec file (docs/recording-format.md), frame by frame (CRCs not checked:
// fusion-replay checks them).
inline std::vector<Frame> ReadFrames(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::vector<Frame> frames;
  for (;;) {
    std::uint32_t head[2];
    if (!in.read(reinterpret_cast<char*>(head), sizeof head)) break;
    std::string payload(head[0], '\0');
    if (!in.read(payload.data(), head[0])) break;
    v1::RecordingFrame record;
    if (!record.ParseFromString(payload)) break;
    if (record.has_cloud()) frames.push_back(FrameOf(record.cloud()));
    if (record.has_index()) break;
  }
  return frames;
}

inline std::size_t FinitePoints(const Frame& frame) {
  std::size_t n = 0;
  for (std::size_t i = 0; i + 2 < frame.xyz.size(); i += 3) {
    n += std::isfinite(frame.xyz[i]) && std::isfinite(frame.xyz[i + 1]) &&
         std::isfinite(frame.xyz[i + 2]);
  }
  return n;
}

}  // namespace fusion::tum_map_bench
