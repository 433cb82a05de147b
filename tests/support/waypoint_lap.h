// A closed lap of waypoints for moving-sensor benchmarks (service_bench's drive, the soak):
// the rig's pose at any time, linearly interpolated between waypoints, the lap repeating.
#pragma once

#include <Eigen/Geometry>
#include <cmath>
#include <vector>

#include "fusion/sim/scene.h"

namespace fusion::testing {

struct Waypoint {
  double t_s, x_m, y_m, z_m, yaw_deg;
};

// The pose at t_s of a lap that starts at lap.front() (t_s = 0) and ends at lap.back(), which
// should equal the start; yaw about +z, looking along +x at yaw 0 (sim::ForwardLookingPose).
inline Eigen::Isometry3d PoseOnLap(const std::vector<Waypoint>& lap, double t_s) {
  const double lap_t_s = std::fmod(t_s, lap.back().t_s);
  std::size_t i = 1;
  while (i + 1 < lap.size() && lap_t_s > lap[i].t_s) ++i;
  const Waypoint& a = lap[i - 1];
  const Waypoint& b = lap[i];
  const double f = (lap_t_s - a.t_s) / (b.t_s - a.t_s);
  const auto mix = [f](double u, double v) { return u + f * (v - u); };
  const Eigen::Vector3d position_m(mix(a.x_m, b.x_m), mix(a.y_m, b.y_m), mix(a.z_m, b.z_m));
  return sim::ForwardLookingPose(position_m, mix(a.yaw_deg, b.yaw_deg) * M_PI / 180.0);
}

}  // namespace fusion::testing
