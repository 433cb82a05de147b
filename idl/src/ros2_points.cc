// ROS 2 range messages to points (fusion/ros2/points.h).
#include <cmath>
#include <cstring>
#include <limits>
#include <stdexcept>

#include "fusion/ros2/points.h"

namespace fusion::ros2 {
namespace {

constexpr bool kHostBigEndian = __BYTE_ORDER__ == __ORDER_BIG_ENDIAN__;
constexpr float kNoReturn = std::numeric_limits<float>::quiet_NaN();

Ros2Reject Reject(Ros2Reject reason, std::string* detail, const std::string& what,
                  std::vector<float>* xyz) {
  xyz->clear();
  if (detail != nullptr) *detail = what;
  return reason;
}

const char* DatatypeName(std::uint8_t datatype) {
  static const char* const kNames[] = {"INT8",  "UINT8",  "INT16",   "UINT16",
                                       "INT32", "UINT32", "FLOAT32", "FLOAT64"};
  return datatype >= 1 && datatype <= 8 ? kNames[datatype - 1] : "unknown";
}

template <class T, bool kSwap>
T Load(const std::uint8_t* p) {
  T value;
  if constexpr (kSwap) {
    std::uint8_t bytes[sizeof(T)];
    for (std::size_t i = 0; i < sizeof(T); ++i) bytes[i] = p[sizeof(T) - 1 - i];
    std::memcpy(&value, bytes, sizeof(T));
  } else {
    std::memcpy(&value, p, sizeof(T));
  }
  return value;
}

void Store(float x, float y, float z, float* out) {
  if (std::isfinite(x) && std::isfinite(y) && std::isfinite(z)) {
    out[0] = x, out[1] = y, out[2] = z;
  } else {
    out[0] = out[1] = out[2] = kNoReturn;
  }
}

template <bool kSwap>
void CopyCloud(const PointCloud2& msg, const std::uint32_t offsets[3], float* out) {
  for (std::uint32_t v = 0; v < msg.height; ++v) {
    const std::uint8_t* point = msg.data.data + std::size_t{v} * msg.row_step;
    for (std::uint32_t u = 0; u < msg.width; ++u, point += msg.point_step, out += 3) {
      Store(Load<float, kSwap>(point + offsets[0]), Load<float, kSwap>(point + offsets[1]),
            Load<float, kSwap>(point + offsets[2]), out);
    }
  }
}

// Pinhole back-projection of the kept pixels; `Depth` reads pixel u of a row in metres.
template <class Depth>
void BackProject(const Image& image, const CameraInfo& info, std::uint32_t stride, Depth depth_m,
                 float* out) {
  const double fx = info.k[0], cx = info.k[2], fy = info.k[4], cy = info.k[5];
  for (std::uint32_t v = 0; v < image.height; v += stride) {
    const std::uint8_t* row = image.data.data + std::size_t{v} * image.step;
    for (std::uint32_t u = 0; u < image.width; u += stride, out += 3) {
      const double z = depth_m(row, u);
      if (!(z > 0) || !std::isfinite(z)) {
        out[0] = out[1] = out[2] = kNoReturn;
        continue;
      }
      out[0] = static_cast<float>((u - cx) * z / fx);
      out[1] = static_cast<float>((v - cy) * z / fy);
      out[2] = static_cast<float>(z);
    }
  }
}

}  // namespace

const char* Ros2RejectName(Ros2Reject reject) {
  switch (reject) {
    case Ros2Reject::kNone:
      return "none";
    case Ros2Reject::kFieldsMissing:
      return "fields_missing";
    case Ros2Reject::kFieldType:
      return "field_type";
    case Ros2Reject::kPointStep:
      return "point_step";
    case Ros2Reject::kDataShort:
      return "data_short";
    case Ros2Reject::kTooLarge:
      return "too_large";
    case Ros2Reject::kEncoding:
      return "encoding";
    case Ros2Reject::kCameraInfo:
      return "camera_info";
  }
  return "unknown";
}

Ros2Reject PointsFromPointCloud2(const PointCloud2& msg, std::size_t max_points,
                                 std::vector<float>* xyz, std::string* detail) {
  static const char* const kAxes[3] = {"x", "y", "z"};
  std::uint32_t offsets[3];
  for (int a = 0; a < 3; ++a) {
    const PointField* field = nullptr;
    for (const PointField& f : msg.fields) {
      if (f.name == kAxes[a]) {
        field = &f;
        break;
      }
    }
    if (field == nullptr) {
      return Reject(Ros2Reject::kFieldsMissing, detail,
                    std::string("no field '") + kAxes[a] + "' among the " +
                        std::to_string(msg.fields.size()) + " fields",
                    xyz);
    }
    if (field->datatype != PointField::FLOAT32) {
      return Reject(Ros2Reject::kFieldType, detail,
                    std::string("field '") + kAxes[a] + "' is " + DatatypeName(field->datatype) +
                        " (" + std::to_string(field->datatype) + "), needs FLOAT32 (7)",
                    xyz);
    }
    if (std::uint64_t{field->offset} + 4 > msg.point_step) {
      return Reject(Ros2Reject::kPointStep, detail,
                    "point_step " + std::to_string(msg.point_step) + " ends before field '" +
                        kAxes[a] + "' (offset " + std::to_string(field->offset) + ", 4 bytes)",
                    xyz);
    }
    offsets[a] = field->offset;
  }
  const std::uint64_t points = std::uint64_t{msg.width} * msg.height;
  if (points > max_points) {
    return Reject(Ros2Reject::kTooLarge, detail,
                  std::to_string(msg.width) + " x " + std::to_string(msg.height) +
                      " points, at most " + std::to_string(max_points) + " allowed",
                  xyz);
  }
  xyz->clear();
  if (points == 0) return Ros2Reject::kNone;
  if (msg.row_step < std::uint64_t{msg.width} * msg.point_step) {
    return Reject(Ros2Reject::kDataShort, detail,
                  "row_step " + std::to_string(msg.row_step) + " < width " +
                      std::to_string(msg.width) + " x point_step " + std::to_string(msg.point_step),
                  xyz);
  }
  if (msg.data.size < std::uint64_t{msg.row_step} * msg.height) {
    return Reject(Ros2Reject::kDataShort, detail,
                  "data holds " + std::to_string(msg.data.size) + " bytes, row_step " +
                      std::to_string(msg.row_step) + " x height " + std::to_string(msg.height) +
                      " needs " + std::to_string(std::uint64_t{msg.row_step} * msg.height),
                  xyz);
  }
  xyz->resize(3 * points);
  if (msg.is_bigendian != kHostBigEndian) {
    CopyCloud<true>(msg, offsets, xyz->data());
  } else {
    CopyCloud<false>(msg, offsets, xyz->data());
  }
  return Ros2Reject::kNone;
}

Ros2Reject PointsFromDepthImage(const Image& image, const CameraInfo& info, int stride,
                                std::size_t max_points, std::vector<float>* xyz,
                                std::string* detail) {
  if (stride < 1) throw std::invalid_argument("PointsFromDepthImage: stride must be >= 1");
  const bool mm16 = image.encoding == "16UC1";
  if (!mm16 && image.encoding != "32FC1") {
    return Reject(Ros2Reject::kEncoding, detail,
                  "encoding '" + image.encoding + "' is not a depth image (16UC1, 32FC1)", xyz);
  }
  if (info.width != image.width || info.height != image.height) {
    return Reject(Ros2Reject::kCameraInfo, detail,
                  "CameraInfo is " + std::to_string(info.width) + " x " +
                      std::to_string(info.height) + ", the image " + std::to_string(image.width) +
                      " x " + std::to_string(image.height),
                  xyz);
  }
  const double fx = info.k[0], cx = info.k[2], fy = info.k[4], cy = info.k[5];
  if (!(std::isfinite(fx) && std::isfinite(fy) && fx != 0 && fy != 0 && std::isfinite(cx) &&
        std::isfinite(cy))) {
    return Reject(Ros2Reject::kCameraInfo, detail,
                  "CameraInfo k has fx " + std::to_string(fx) + ", fy " + std::to_string(fy) +
                      ", cx " + std::to_string(cx) + ", cy " + std::to_string(cy) +
                      ": focal lengths must be non-zero, all finite",
                  xyz);
  }
  const std::uint64_t points =
      std::uint64_t{StridedSize(image.width, stride)} * StridedSize(image.height, stride);
  if (points > max_points) {
    return Reject(Ros2Reject::kTooLarge, detail,
                  std::to_string(points) + " points (stride " + std::to_string(stride) +
                      "), at most " + std::to_string(max_points) + " allowed",
                  xyz);
  }
  xyz->clear();
  if (points == 0) return Ros2Reject::kNone;
  const std::uint64_t pixel_bytes = mm16 ? 2 : 4;
  if (image.step < image.width * pixel_bytes) {
    return Reject(Ros2Reject::kDataShort, detail,
                  "step " + std::to_string(image.step) + " < width " + std::to_string(image.width) +
                      " x " + std::to_string(pixel_bytes) + " bytes",
                  xyz);
  }
  if (image.data.size < std::uint64_t{image.step} * image.height) {
    return Reject(Ros2Reject::kDataShort, detail,
                  "data holds " + std::to_string(image.data.size) + " bytes, step " +
                      std::to_string(image.step) + " x height " + std::to_string(image.height) +
                      " needs " + std::to_string(std::uint64_t{image.step} * image.height),
                  xyz);
  }
  xyz->resize(3 * points);
  const bool swap = (image.is_bigendian != 0) != kHostBigEndian;
  const auto s = static_cast<std::uint32_t>(stride);
  if (mm16) {
    BackProject(
        image, info, s,
        [swap](const std::uint8_t* row, std::uint32_t u) {
          const std::uint8_t* p = row + 2 * std::size_t{u};
          return 1e-3 * (swap ? Load<std::uint16_t, true>(p) : Load<std::uint16_t, false>(p));
        },
        xyz->data());
  } else {
    BackProject(
        image, info, s,
        [swap](const std::uint8_t* row, std::uint32_t u) {
          const std::uint8_t* p = row + 4 * std::size_t{u};
          return double{swap ? Load<float, true>(p) : Load<float, false>(p)};
        },
        xyz->data());
  }
  return Ros2Reject::kNone;
}

}  // namespace fusion::ros2
