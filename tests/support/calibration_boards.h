// The calibration tests' target: a square board facing a sensor at the origin (world x
// forward), its plane x = distance_m.
#pragma once

#include <Eigen/Geometry>

#include "fusion/sim/scene.h"

namespace fusion::testing {

inline sim::Scene BoardAt(double distance_m, double half_edge_m = 10.0) {
  sim::Scene scene;
  sim::Rectangle board;
  board.name = "board";
  board.center_m = Eigen::Vector3d(distance_m, 0.0, 0.0);
  board.axis_u = Eigen::Vector3d::UnitY();
  board.axis_v = Eigen::Vector3d::UnitZ();
  board.half_u_m = board.half_v_m = half_edge_m;
  scene.AddRectangle(board);
  return scene;
}

}  // namespace fusion::testing
