#include "fusion/sim/ground_truth.h"

#include "fusion/core/beam_grid.h"
#include "fusion/core/local_grid.h"
#include "fusion/core/voxel_traversal.h"

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
      // The renderer's traversal (fusion/core/voxel_traversal.h) from r_min to the hit, so the
      // oracle labels the voxels the renderer writes, boundaries included.
      ForEachVoxel(origin, dir, t_start, t_end, res, [&](const VoxelTraversal& voxel) {
        const long idx[3] = {voxel.index(0), voxel.index(1), voxel.index(2)};
        const octomap::OcTreeKey key = voxel.Key();
        if (labels.labels.find(key) == labels.labels.end()) {
          labels.labels.emplace(key, scene.SurfaceIntersects(voxel_box(idx)));
        }
      });
      if (hit) {
        // The hit point's voxel is occupied even if floating point put the
        // walk's last voxel a hair short of it.
        const Eigen::Vector3d p = origin + dir * hit->range_m;
        if (InsideMap(p, res)) labels.labels[KeyOfPoint(p, res)] = true;
      }
    }
  }
  return labels;
}

SurfaceDistanceFn SurfaceDistance(const Scene& scene) {
  return [scene](const Eigen::Vector3d& p) { return scene.DistanceToSurface(p); };
}

}  // namespace fusion::sim
