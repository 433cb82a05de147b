// Ground-truth voxel labels of a scene for the accuracy harness
// (fusion/core/accuracy.h).
#pragma once

#include <Eigen/Geometry>
#include <vector>

#include "fusion/core/accuracy.h"
#include "fusion/core/sensor.h"
#include "fusion/sim/scene.h"

namespace fusion::sim {

struct View {
  SensorSpec spec;
  Eigen::Isometry3d T_world_sensor = Eigen::Isometry3d::Identity();
  // A ray that hits nothing within r_max observes free space only if the sensor
  // reports beyond-range returns (SimOptions::flag_beyond_range).
  bool beyond_range_observed = true;
  // A ray that hits an untextured surface observes nothing
  // (SimOptions::require_texture).
  bool require_texture = false;
};

// Casts the noise-free centre ray of every beam of every view: voxels a ray
// crosses between r_min and its hit (or r_max) are free unless a surface passes
// through them; voxels a surface passes through that a ray reaches are
// occupied.
[[nodiscard]] VoxelLabels LabelVoxels(const Scene& scene, const std::vector<View>& views,
                                      double resolution_m);
// The scene's surface distance as the harness wants it.
[[nodiscard]] SurfaceDistanceFn SurfaceDistance(const Scene& scene);

}  // namespace fusion::sim
