// Helpers for building fusion.v1 requests, shared by the integration tests' fixture
// (fusiond_fixture.h) and the service benchmarks; no gtest, so that benchmarks can use them.
#pragma once

#include <Eigen/Core>
#include <chrono>

#include "fusion/v1/map_service.pb.h"

namespace fusion::testing {

// A world-frame point (metres) as the wire's Point.
inline fusion::v1::Point P(const Eigen::Vector3d& v) {
  fusion::v1::Point p;
  p.set_x(v.x());
  p.set_y(v.y());
  p.set_z(v.z());
  return p;
}

// A gRPC deadline `ms` from now.
inline std::chrono::system_clock::time_point In(std::chrono::milliseconds ms) {
  return std::chrono::system_clock::now() + ms;
}

}  // namespace fusion::testing
