// DDS ingest: a sample as Cyclone hands it over (every sequence's buffer really holds _length
// elements), ValidateSample, and CloudFromDds for what it accepts.
//
// Layout (little-endian; missing bytes read as zero):
//   u8 flags   bit 0: sensor_id is null          bit 1: pose as raw doubles (else q normalized)
//              bit 2: xyz has 3 x width x height  bit 3: beyond_range has width x height
//              bit 4: every sensor id is known (else only "sr" and "stoc")
//   u8 id_length, id bytes | u64 sequence | i32 sec | u32 nanosec | f64 tx ty tz qx qy qz qw
//   u32 width | u32 height | u16 xyz_count (unless bit 2) | u16 beyond_count (unless bit 3)
//   u32 max_points | u16 quaternion_tolerance | f64 max_abs_translation_m | f64 map_resolution_m
//   then the xyz floats and the beyond_range bytes.
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstring>

#include "common.h"
#include "fusion/core/local_grid.h"
#include "fusion/service/conversions.h"
#include "fusion/service/validation.h"

namespace fusion::fuzz {
namespace {

constexpr std::uint64_t kMaxXyzValues = 3 * 4096;  // what one input may allocate
constexpr std::uint8_t kNullId = 1, kRawPose = 2, kXyzMatches = 4, kBeyondMatches = 8,
                       kAllKnown = 16;

class Bytes {
 public:
  Bytes(const std::uint8_t* data, std::size_t size) : data_(data), size_(size) {}
  template <typename T>
  T Take() {
    T value{};
    const std::size_t n = std::min(sizeof value, size_ - at_);
    std::memcpy(&value, data_ + at_, n);
    at_ += n;
    return value;
  }
  // `count` values, copied at once (zero where the input ends).
  template <typename T>
  std::vector<T> TakeVector(std::uint64_t count) {
    std::vector<T> values(count);
    const std::size_t n = std::min<std::size_t>(count * sizeof(T), size_ - at_);
    if (n > 0) std::memcpy(values.data(), data_ + at_, n);
    at_ += n;
    return values;
  }
  std::string TakeString(std::size_t length) {
    const std::size_t n = std::min(length, size_ - at_);
    std::string text(reinterpret_cast<const char*>(data_ + at_), n);
    at_ += n;
    return text;
  }

 private:
  const std::uint8_t* data_;
  std::size_t size_;
  std::size_t at_ = 0;
};

void NormalizeQuaternion(fusion_dds_Pose* p) {
  const double norm = std::sqrt(p->qx * p->qx + p->qy * p->qy + p->qz * p->qz + p->qw * p->qw);
  if (!(norm > 1e-6) || !std::isfinite(norm)) return;
  p->qx /= norm, p->qy /= norm, p->qz /= norm, p->qw /= norm;
}

service::IngestLimits TakeLimits(Bytes* in) {
  service::IngestLimits limits;
  limits.max_points = 1 + in->Take<std::uint32_t>() % 50'000'000;  // the config's range
  const auto tolerance = in->Take<std::uint16_t>();
  if (tolerance != 0) limits.quaternion_tolerance = tolerance / 131072.0;  // (0, 0.5)
  const double translation_m = in->Take<double>();
  if (translation_m > 0 && std::isfinite(translation_m))
    limits.max_abs_translation_m = translation_m;
  const double resolution_m = in->Take<double>();
  limits.map_resolution_m = resolution_m >= 0.001 && resolution_m <= 10 ? resolution_m : 0.0;
  return limits;
}

Outcome CheckRejection(service::RejectReason reason, const std::string& detail) {
  if (std::string(service::RejectReasonName(reason)) == "unknown_reason") {
    return Broken("reason without a name: " + std::to_string(static_cast<int>(reason)));
  }
  return Rejected(detail);
}

Outcome CheckCloud(const fusion_dds_PointCloud& sample, const service::IngestLimits& limits) {
  const service::Cloud cloud = service::CloudFromDds(sample);
  const std::uint64_t points = std::uint64_t{sample.width} * sample.height;
  if (cloud.sensor_id != sample.sensor_id) return Broken("sensor id changed in conversion");
  if (cloud.xyz.size() != 3 * points) return Broken("xyz size differs from 3 x width x height");
  if (!cloud.beyond_range.empty() && cloud.beyond_range.size() != points) {
    return Broken("beyond_range size differs from width x height");
  }
  if (!cloud.T_world_published.matrix().allFinite()) return Broken("accepted pose is not finite");
  const Eigen::Matrix3d R = cloud.T_world_published.linear();
  if ((R.transpose() * R - Eigen::Matrix3d::Identity()).norm() > 1e-6) {
    return Broken("accepted pose's rotation is not orthonormal");
  }
  if (limits.map_resolution_m > 0 &&
      !InsideMap(cloud.T_world_published.translation(), limits.map_resolution_m)) {
    return Broken("accepted pose lies outside the map");
  }
  return Accepted();
}

// Untrusted text in a log line: printable ASCII only, bounded.
Outcome CheckLoggable(const std::string& id) {
  const std::string text = service::LoggableText(id);
  if (text.size() > 4 * 64 + 32) return Broken("LoggableText kept too much");
  for (const char c : text) {
    if (c < 0x20 || c > 0x7e) return Broken("LoggableText let a control byte through");
  }
  return Accepted();
}

}  // namespace

Outcome RunDdsSample(const std::uint8_t* data, std::size_t size) {
  Bytes in(data, size);
  const auto flags = in.Take<std::uint8_t>();
  std::string id = in.TakeString(in.Take<std::uint8_t>());
  if (Outcome o = CheckLoggable(id); o.verdict == Verdict::kBroken) return o;
  fusion_dds_PointCloud sample{};
  sample.sensor_id = (flags & kNullId) != 0 ? nullptr : id.data();
  sample.sequence_number = in.Take<std::uint64_t>();
  sample.stamp.sec = in.Take<std::int32_t>();
  sample.stamp.nanosec = in.Take<std::uint32_t>();
  for (double* v : {&sample.T_world_sensor.tx, &sample.T_world_sensor.ty, &sample.T_world_sensor.tz,
                    &sample.T_world_sensor.qx, &sample.T_world_sensor.qy, &sample.T_world_sensor.qz,
                    &sample.T_world_sensor.qw}) {
    *v = in.Take<double>();
  }
  if ((flags & kRawPose) == 0) NormalizeQuaternion(&sample.T_world_sensor);
  sample.width = in.Take<std::uint32_t>();
  sample.height = in.Take<std::uint32_t>();
  const std::uint64_t points = std::uint64_t{sample.width} * sample.height;
  const std::uint64_t xyz_count =
      std::min(kMaxXyzValues, (flags & kXyzMatches) != 0 ? 3 * points : in.Take<std::uint16_t>());
  const std::uint64_t beyond_count =
      std::min(kMaxXyzValues, (flags & kBeyondMatches) != 0 ? points : in.Take<std::uint16_t>());
  const service::IngestLimits limits = TakeLimits(&in);
  std::vector<float> xyz = in.TakeVector<float>(xyz_count);
  std::vector<std::uint8_t> beyond = in.TakeVector<std::uint8_t>(beyond_count);
  sample.xyz = {static_cast<std::uint32_t>(xyz.size()), static_cast<std::uint32_t>(xyz.size()),
                xyz.empty() ? nullptr : xyz.data(), false};
  sample.beyond_range = {static_cast<std::uint32_t>(beyond.size()),
                         static_cast<std::uint32_t>(beyond.size()),
                         beyond.empty() ? nullptr : beyond.data(), false};
  const auto known = [&](const std::string& s) {
    return (flags & kAllKnown) != 0 || s == "sr" || s == "stoc";
  };
  std::string detail;
  const auto reason = service::ValidateSample(sample, limits, known, &detail);
  if (reason) return CheckRejection(*reason, detail);
  return CheckCloud(sample, limits);
}

std::string EncodeDdsSample(const DdsSampleSeed& seed) {
  std::string out;
  const auto put = [&out](const auto& v) {
    out.append(reinterpret_cast<const char*>(&v), sizeof v);
  };
  put(static_cast<std::uint8_t>(kXyzMatches | (seed.beyond_range.empty() ? 0 : kBeyondMatches)));
  put(static_cast<std::uint8_t>(seed.sensor_id.size()));
  out += seed.sensor_id.substr(0, 255);
  put(std::uint64_t{1});
  put(std::int32_t{1'700'000'000});
  put(std::uint32_t{0});
  for (const double v : seed.pose) put(v);
  put(seed.width);
  put(seed.height);
  if (seed.beyond_range.empty()) put(std::uint16_t{0});
  put(std::uint32_t{3'999'999});  // max_points 4'000'000
  put(std::uint16_t{131});        // quaternion tolerance ~1e-3
  put(1e5);
  put(seed.map_resolution_m);
  for (const float v : seed.xyz) put(v);
  for (const std::uint8_t v : seed.beyond_range) put(v);
  return out;
}

}  // namespace fusion::fuzz
