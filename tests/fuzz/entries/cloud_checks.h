// What an importer's cloud must look like when it reports success.
#pragma once

#include <cmath>
#include <string>

#include "common.h"
#include "fusion/v1/recording.pb.h"

namespace fusion::fuzz {

// xyz_f32le holds width x height points.
inline Outcome CheckShape(const fusion::v1::RecordedCloud& cloud) {
  const std::uint64_t points = std::uint64_t{cloud.width()} * cloud.height();
  if (cloud.xyz_f32le().size() != 12 * points) {
    return Broken("cloud of " + std::to_string(cloud.width()) + " x " +
                  std::to_string(cloud.height()) + " points holds " +
                  std::to_string(cloud.xyz_f32le().size()) + " bytes of xyz");
  }
  return Accepted();
}

// The importer normalizes the pose: finite, unit quaternion.
inline Outcome CheckUnitPose(const fusion::v1::RecordedPose& p) {
  const double values[] = {p.tx(), p.ty(), p.tz(), p.qx(), p.qy(), p.qz(), p.qw()};
  for (const double v : values) {
    if (!std::isfinite(v)) return Broken("imported pose is not finite");
  }
  const double norm =
      std::sqrt(p.qx() * p.qx() + p.qy() * p.qy() + p.qz() * p.qz() + p.qw() * p.qw());
  if (std::abs(norm - 1.0) > 1e-5) {  // OctoMap's float poses: ~1e-7
    return Broken("imported quaternion has norm " + std::to_string(norm));
  }
  return Accepted();
}

}  // namespace fusion::fuzz
