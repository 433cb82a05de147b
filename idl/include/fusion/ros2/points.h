// THE conversion of ROS 2 range messages into points, shared by fusiond's live ingest and
// fusion-import rosbag2: sensor_msgs/PointCloud2 and depth sensor_msgs/Image + CameraInfo to
// packed float x y z in the message's frame (header.frame_id), metres, NaN = no return.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "fusion/ros2/messages.h"

namespace fusion::ros2 {

// Why a message gives no points (kNone: it did).
enum class Ros2Reject {
  kNone,
  kFieldsMissing,  // no x, y or z field
  kFieldType,      // x, y or z not FLOAT32
  kPointStep,      // point_step smaller than the x/y/z fields need
  kDataShort,      // data shorter than the rows, or a row shorter than its points
  kTooLarge,       // more points than allowed
  kEncoding,       // an image encoding that is not depth (16UC1, 32FC1)
  kCameraInfo,     // CameraInfo unusable for the image (focal length 0, other size)
};

// "fields_missing", "field_type", "point_step", "data_short", "too_large", "encoding",
// "camera_info" ("none" for kNone): metric labels and counters.
const char* Ros2RejectName(Ros2Reject reject);

// PointCloud2 -> *xyz (3 floats a point, width * height points): unorganized (height 1) in
// message order, organized (height > 1) in pixel order (row-major). x, y, z are located by
// name (other fields skipped) at any offset, point_step and row_step; they must be FLOAT32
// (FLOAT64 is kFieldType). is_bigendian is honoured. A point with a NaN or infinite coordinate
// is no return (all three NaN). An empty cloud gives kNone with no points. On a rejection
// *xyz is empty and `detail` (if given) says exactly what is wrong.
Ros2Reject PointsFromPointCloud2(const PointCloud2& msg, std::size_t max_points,
                                 std::vector<float>* xyz, std::string* detail = nullptr);

// Depth image -> *xyz in the camera's optical frame (x right, y down, z forward, metres).
// Encodings 16UC1 (millimetres) and 32FC1 (metres); 0, NaN, inf and negative depths are no
// return. is_bigendian and step are honoured. Pixels u = 0, stride, 2 stride, ... (and the same
// for v) give StridedSize(width, stride) x StridedSize(height, stride) points in pixel order:
// ((u - cx) z / fx, (v - cy) z / fy, z) with fx = k[0], cx = k[2], fy = k[4], cy = k[5].
// stride must be >= 1 (std::invalid_argument otherwise: a caller's bug, not bad data).
// CameraInfo's binning and roi are not applied: K must be the image's own.
Ros2Reject PointsFromDepthImage(const Image& image, const CameraInfo& info, int stride,
                                std::size_t max_points, std::vector<float>* xyz,
                                std::string* detail = nullptr);

// Pixels kept of `pixels` with every stride-th taken from the first: ceil(pixels / stride).
inline std::uint32_t StridedSize(std::uint32_t pixels, int stride) {
  const auto s = static_cast<std::uint64_t>(stride);
  return static_cast<std::uint32_t>((pixels + s - 1) / s);
}

}  // namespace fusion::ros2
