// ROS 2 messages as fusiond's ingest and fusion-import rosbag2 read them: the bytes decoded as
// XCDR1 PointCloud2 (then PointsFromPointCloud2), Image (then PointsFromDepthImage with a
// CameraInfo of its size), CameraInfo and TFMessage. What decodes must encode and decode again
// to the same bytes; what converts must give 3 floats a point.
#include "common.h"
#include "fusion/ros2/cdr.h"
#include "fusion/ros2/points.h"

namespace fusion::fuzz {
namespace {

using Bytes = std::vector<std::uint8_t>;

// Enough for any input the fuzzer makes (-max_len), small enough for its memory limit.
constexpr std::size_t kMaxPoints = 1u << 22;

// Decoded once: encoding it and decoding that must give the same bytes again.
template <class Message>
Outcome RoundTrip(const Message& decoded, const char* name) {
  const Bytes once = ros2::EncodeCdr(decoded);
  Message again;
  if (const ros2::CdrResult r = ros2::DecodeCdr(ros2::ByteView(once), &again); !r.ok()) {
    return Broken(std::string(name) + " re-encoded does not decode: " + r.error);
  }
  if (ros2::EncodeCdr(again) != once) return Broken(std::string(name) + " round trip differs");
  if (ros2::EncodeCdr(decoded, ros2::CdrEndian::kBig).size() != once.size()) {
    return Broken(std::string(name) + " big-endian encoding has another size");
  }
  return Accepted();
}

Outcome CheckPoints(ros2::Ros2Reject reject, std::uint64_t points, const std::vector<float>& xyz,
                    const std::string& detail) {
  if (reject != ros2::Ros2Reject::kNone) {
    if (detail.empty())
      return Broken(std::string(ros2::Ros2RejectName(reject)) + " without detail");
    if (!xyz.empty()) return Broken("rejected but points returned");
    return Rejected(std::string(ros2::Ros2RejectName(reject)) + ": " + detail);
  }
  if (xyz.size() != 3 * points) {
    return Broken(std::to_string(xyz.size()) + " floats for " + std::to_string(points) + " points");
  }
  return Accepted();
}

Outcome RunCloud(ros2::ByteView bytes) {
  ros2::PointCloud2 cloud;
  if (const ros2::CdrResult r = ros2::DecodeCdr(bytes, &cloud); !r.ok()) return Rejected(r.error);
  if (Outcome o = RoundTrip(cloud, "PointCloud2"); o.verdict == Verdict::kBroken) return o;
  std::vector<float> xyz;
  std::string detail;
  const ros2::Ros2Reject reject = ros2::PointsFromPointCloud2(cloud, kMaxPoints, &xyz, &detail);
  return CheckPoints(reject, std::uint64_t{cloud.width} * cloud.height, xyz, detail);
}

Outcome RunDepth(ros2::ByteView bytes) {
  ros2::Image image;
  if (const ros2::CdrResult r = ros2::DecodeCdr(bytes, &image); !r.ok()) return Rejected(r.error);
  if (Outcome o = RoundTrip(image, "Image"); o.verdict == Verdict::kBroken) return o;
  ros2::CameraInfo info;
  info.width = image.width, info.height = image.height;
  info.k = {500, 0, image.width / 2.0, 0, 500, image.height / 2.0, 0, 0, 1};
  const int stride = 1 + static_cast<int>(image.header.stamp.nanosec % 4);
  std::vector<float> xyz;
  std::string detail;
  const ros2::Ros2Reject reject =
      ros2::PointsFromDepthImage(image, info, stride, kMaxPoints, &xyz, &detail);
  const std::uint64_t points = std::uint64_t{ros2::StridedSize(image.width, stride)} *
                               ros2::StridedSize(image.height, stride);
  return CheckPoints(reject, points, xyz, detail);
}

template <class Message>
Outcome RunMessage(ros2::ByteView bytes, const char* name) {
  Message message;
  if (const ros2::CdrResult r = ros2::DecodeCdr(bytes, &message); !r.ok()) return Rejected(r.error);
  return RoundTrip(message, name);
}

}  // namespace

Outcome RunRos2Cdr(const std::uint8_t* data, std::size_t size) {
  const ros2::ByteView bytes(data, size);
  Outcome outcomes[] = {RunCloud(bytes), RunDepth(bytes),
                        RunMessage<ros2::CameraInfo>(bytes, "CameraInfo"),
                        RunMessage<ros2::TFMessage>(bytes, "TFMessage")};
  for (Outcome& o : outcomes) {
    if (o.verdict == Verdict::kBroken) return o;
  }
  // Accepted as one of the four kinds, otherwise the cloud's rejection (fusiond's ingest).
  for (Outcome& o : outcomes) {
    if (o.verdict == Verdict::kAccepted) return o;
  }
  return outcomes[0];
}

}  // namespace fusion::fuzz
