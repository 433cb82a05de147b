// TUM RGB-D importer: groundtruth.txt lists depth PNGs with the optical frame's pose in the
// world; each depth image becomes an organized cloud in the optical frame.
#include <cerrno>
#include <cmath>
#include <cstring>
#include <fstream>
#include <limits>
#include <sstream>

#include "fusion/clients/cli.h"
#include "fusion/clients/importers.h"

namespace fusion::clients {
namespace {

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

// One groundtruth.txt line: "depth/x.png tx ty tz qx qy qz qw".
struct GroundtruthEntry {
  std::string depth_file;                    // relative to the sequence directory
  fusion::v1::RecordedPose t_world_optical;  // quaternion normalised
  fusion::v1::RecordedTime stamp;            // from the file name
};

Status ParseGroundtruthLine(const std::string& line, const std::string& where,
                            GroundtruthEntry* entry) {
  std::istringstream fields(line);
  double p[7];
  if (!(fields >> entry->depth_file >> p[0] >> p[1] >> p[2] >> p[3] >> p[4] >> p[5] >> p[6])) {
    return Status::Error(where + ": expected 'depth_file tx ty tz qx qy qz qw'");
  }
  const double norm = std::sqrt(p[3] * p[3] + p[4] * p[4] + p[5] * p[5] + p[6] * p[6]);
  if (!(std::abs(norm - 1.0) < 1e-2)) {
    return Status::Error(where + ": quaternion is not unit length (norm " + std::to_string(norm) +
                         ")");
  }
  // The file name is the capture time: depth/1311877813.991479.png.
  const std::string& file = entry->depth_file;
  std::string base = file.substr(file.find_last_of('/') + 1);
  base = base.substr(0, base.rfind(".png"));
  if (Status s = ParseStamp(where + ": time stamp in file name", base, &entry->stamp); !s.ok()) {
    return s;
  }
  auto* pose = &entry->t_world_optical;
  pose->set_tx(p[0]);
  pose->set_ty(p[1]);
  pose->set_tz(p[2]);
  pose->set_qx(p[3] / norm);
  pose->set_qy(p[4] / norm);
  pose->set_qz(p[5] / norm);
  pose->set_qw(p[6] / norm);
  return Status::Ok();
}

// Back-projects every stride-th pixel of a depth image into the optical frame (x right, y down,
// z forward, metres); missing depth (0) becomes a NaN point, so the cloud stays organized.
void DepthToCloud(const TumOptions& options, std::uint32_t width, std::uint32_t height,
                  const std::vector<std::uint16_t>& depth, fusion::v1::RecordedCloud* cloud) {
  const std::uint32_t out_width = (width + options.stride - 1) / options.stride;
  const std::uint32_t out_height = (height + options.stride - 1) / options.stride;
  cloud->set_width(out_width);
  cloud->set_height(out_height);
  cloud->mutable_xyz_f32le()->reserve(static_cast<std::size_t>(out_width) * out_height * 12);
  for (std::uint32_t v = 0; v < height; v += options.stride) {
    for (std::uint32_t u = 0; u < width; u += options.stride) {
      const std::uint16_t raw = depth[static_cast<std::size_t>(v) * width + u];
      if (raw == 0) {  // missing measurement: no information, not free space
        AppendPoint(kNaN, kNaN, kNaN, cloud);
        continue;
      }
      const double z_m = raw / options.depth_scale;
      AppendPoint(static_cast<float>((u - options.cx_px) * z_m / options.fx_px),
                  static_cast<float>((v - options.cy_px) * z_m / options.fy_px),
                  static_cast<float>(z_m), cloud);
    }
  }
}

}  // namespace

Status ImportTum(const TumOptions& options, const CloudSink& sink, ImageSize* image_size) {
  if (options.stride == 0) return Status::Error("--stride must be at least 1");
  if (!(options.fx_px > 0 && options.fy_px > 0 && options.depth_scale > 0)) {
    return Status::Error("focal lengths and depth scale must be positive");
  }
  const std::string list_path = options.directory + "/" + options.groundtruth;
  std::ifstream list(list_path);
  if (!list) return Status::Error("cannot open " + list_path + ": " + std::strerror(errno));
  std::string line;
  std::uint64_t line_number = 0, frames = 0;
  while (std::getline(list, line)) {
    ++line_number;
    if (line.empty() || line[0] == '#') continue;
    const std::string where = list_path + ":" + std::to_string(line_number);
    GroundtruthEntry entry;
    if (Status s = ParseGroundtruthLine(line, where, &entry); !s.ok()) return s;

    std::uint32_t width = 0, height = 0;
    std::vector<std::uint16_t> depth;
    if (Status s = ReadPng16(options.directory + "/" + entry.depth_file, &width, &height, &depth);
        !s.ok()) {
      return s.WithContext(where);
    }
    if (image_size != nullptr) *image_size = {width, height};
    fusion::v1::RecordedCloud cloud;
    *cloud.mutable_t_world_sensor() = entry.t_world_optical;
    DepthToCloud(options, width, height, depth, &cloud);
    ++frames;
    SetIdentity(options.sensor_id, frames, 0.0, entry.depth_file, &cloud);
    *cloud.mutable_stamp() = entry.stamp;
    cloud.set_receive_time_unix_ns(static_cast<std::int64_t>(entry.stamp.sec()) * 1000000000 +
                                   entry.stamp.nanosec());
    if (Status s = sink(std::move(cloud)); !s.ok()) return s;
    if (options.max_frames != 0 && frames >= options.max_frames) break;
  }
  if (frames == 0) return Status::Error(list_path + ": no frames listed");
  return Status::Ok();
}

}  // namespace fusion::clients
