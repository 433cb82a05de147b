// Point access and identity of RecordedCloud messages, shared by every importer.
#include <cmath>
#include <cstring>

#include "fusion/clients/cli.h"
#include "fusion/clients/importers.h"

namespace fusion::clients {

static_assert(__BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__,
              "xyz_f32le is written with memcpy: little-endian hosts only");

void AppendPoint(float x, float y, float z, fusion::v1::RecordedCloud* cloud) {
  const float xyz[3] = {x, y, z};
  cloud->mutable_xyz_f32le()->append(reinterpret_cast<const char*>(xyz), sizeof xyz);
}

void GetPoint(const fusion::v1::RecordedCloud& cloud, std::size_t i, float xyz[3]) {
  std::memcpy(xyz, cloud.xyz_f32le().data() + 12 * i, 12);
}

double FractionBehindSensor(const fusion::v1::RecordedCloud& cloud) {
  const std::size_t n = cloud.xyz_f32le().size() / 12;
  std::size_t finite = 0, behind = 0;
  for (std::size_t i = 0; i < n; ++i) {
    float p[3];
    GetPoint(cloud, i, p);
    if (!std::isfinite(p[0]) || !std::isfinite(p[1]) || !std::isfinite(p[2])) continue;
    ++finite;
    if (p[2] < 0) ++behind;
  }
  return finite ? static_cast<double>(behind) / static_cast<double>(finite) : 0.0;
}

void SetIdentity(const std::string& sensor_id, std::uint64_t sequence_number, double stamp_s,
                 const std::string& origin, fusion::v1::RecordedCloud* cloud) {
  cloud->set_sensor_id(sensor_id);
  cloud->set_sequence_number(sequence_number);
  *cloud->mutable_stamp() = TimeFromSeconds(stamp_s);
  cloud->set_receive_time_unix_ns(static_cast<std::int64_t>(cloud->stamp().sec()) * 1000000000 +
                                  cloud->stamp().nanosec());
  cloud->set_origin(origin);
}

}  // namespace fusion::clients
