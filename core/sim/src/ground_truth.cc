#include "fusion/sim/ground_truth.h"

#include <cmath>
#include <limits>

#include "fusion/core/beam_grid.h"
#include "fusion/core/local_grid.h"

namespace fusion::sim {

VoxelLabels LabelVoxels(const Scene& scene, const std::vector<View>& views, double resolution_m) {
  VoxelLabels labels;
  labels.resolution_m = resolution_m;
  const double res = resolution_m;
  auto voxel_box = [res](const long idx[3]) {
    const Eigen::Vector3d lo(idx[0] * res, idx[1] * res, idx[2] * res);
    return Eigen::AlignedBox3d(lo, lo + Eigen::Vector3d::Constant(res));
  };
  for (const View& view : views) {
    const BeamTessellation tess(view.spec);
    const Eigen::Vector3d origin = view.T_world_sensor.translation();
    for (std::size_t b = 0; b < tess.beam_count(); ++b) {
      const Eigen::Vector3d dir = view.T_world_sensor.linear() * tess.Direction(b);
      const auto hit = scene.Raycast(origin, dir, view.spec.r_max_m);
      if (!hit && !view.beyond_range_observed) continue;
      if (hit && view.require_texture && !hit->textured) continue;
      const double t_end = hit ? hit->range_m : view.spec.r_max_m;
      const double t_start = view.spec.r_min_m;
      if (t_end <= t_start) continue;
      // Amanatides & Woo from r_min to the hit.
      const Eigen::Vector3d p0 = origin + dir * t_start;
      long idx[3];
      int step[3];
      double t_max[3];
      double t_delta[3];
      for (int a = 0; a < 3; ++a) {
        idx[a] = static_cast<long>(std::floor(p0[a] / res));
        if (dir[a] > 0) {
          step[a] = 1;
          t_max[a] = t_start + ((idx[a] + 1) * res - p0[a]) / dir[a];
          t_delta[a] = res / dir[a];
        } else if (dir[a] < 0) {
          step[a] = -1;
          t_max[a] = t_start + (idx[a] * res - p0[a]) / dir[a];
          t_delta[a] = -res / dir[a];
        } else {
          step[a] = 0;
          t_max[a] = t_delta[a] = std::numeric_limits<double>::infinity();
        }
      }
      double t = t_start;
      while (true) {
        const Eigen::AlignedBox3d box = voxel_box(idx);
        const octomap::OcTreeKey key = KeyOfPoint(box.center(), res);
        auto it = labels.labels.find(key);
        if (it == labels.labels.end()) {
          labels.labels.emplace(key, scene.SurfaceIntersects(box));
        }
        const int axis =
            (t_max[0] < t_max[1]) ? (t_max[0] < t_max[2] ? 0 : 2) : (t_max[1] < t_max[2] ? 1 : 2);
        if (t_max[axis] >= t_end) break;  // this voxel holds the hit (or the end of range)
        t = t_max[axis];
        idx[axis] += step[axis];
        t_max[axis] += t_delta[axis];
      }
      (void)t;
      if (hit) {
        // The hit point's voxel is occupied even if floating point put the
        // walk's last voxel a hair short of it.
        const Eigen::Vector3d p = origin + dir * hit->range_m;
        labels.labels[KeyOfPoint(p, res)] = true;
      }
    }
  }
  return labels;
}

SurfaceDistanceFn SurfaceDistance(const Scene& scene) {
  return [scene](const Eigen::Vector3d& p) { return scene.DistanceToSurface(p); };
}

}  // namespace fusion::sim
