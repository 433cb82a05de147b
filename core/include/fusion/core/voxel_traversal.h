// The voxels a ray crosses, in order (Amanatides & Woo, "A Fast Voxel Traversal Algorithm for
// Ray Tracing", 1987). Written once for the renderer (detail::BeamTracer) and for its oracle,
// the simulator's ground truth (sim::LabelVoxels): both floor the same products and step over
// the same face ranges, so they cannot disagree about which voxel a ray is in at a boundary.
//
// World frame, metres. Voxel index i on an axis covers [i * resolution, (i + 1) * resolution);
// its OctoMap key (tree depth 16) is i + kMapKeyOffset, which fits a key only inside
// [-kMapKeyOffset, kMapKeyOffset): beyond, the uint16 key would wrap to the far side of the map.
#pragma once

#include <octomap/OcTree.h>

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <limits>

namespace fusion {

// OctoMap's tree_max_val at depth 16: the key of voxel index 0.
inline constexpr int kMapKeyOffset = 32768;

// Whether a voxel index (world coordinate / resolution, floored) has an OctoMap key.
[[nodiscard]] inline bool InKeyRange(long index) {
  return index >= -kMapKeyOffset && index < kMapKeyOffset;
}

// A walk along the ray p(t) = origin + t * dir from range t_first on, voxel by voxel. t is in
// metres along the ray when dir is a unit vector. Cheap to construct (one per ray) and meant to
// live on the stack of the loop that drives it: the caller decides where the walk ends.
class VoxelTraversal {
 public:
  VoxelTraversal(const Eigen::Vector3d& origin, const Eigen::Vector3d& dir, double t_first,
                 double resolution_m) {
    const double res = resolution_m;
    // One inverse, multiplied: the index of a point is floor(p * (1 / res)) wherever it is taken.
    const double inv_res = 1.0 / res;
    const Eigen::Vector3d p0 = origin + dir * t_first;
    for (int a = 0; a < 3; ++a) {
      index_[a] = static_cast<long>(std::floor(p0[a] * inv_res));
      if (dir[a] > 0.0) {
        step_[a] = 1;
        t_max_[a] = t_first + ((index_[a] + 1) * res - p0[a]) / dir[a];
        t_delta_[a] = res / dir[a];
        entry_ = std::max(entry_, t_first + (index_[a] * res - p0[a]) / dir[a]);
      } else if (dir[a] < 0.0) {
        step_[a] = -1;
        t_max_[a] = t_first + (index_[a] * res - p0[a]) / dir[a];
        t_delta_[a] = -res / dir[a];
        entry_ = std::max(entry_, t_first + ((index_[a] + 1) * res - p0[a]) / dir[a]);
      } else {
        step_[a] = 0;
        t_max_[a] = std::numeric_limits<double>::infinity();
        t_delta_[a] = std::numeric_limits<double>::infinity();
      }
    }
  }

  // Index of the current voxel on axis a.
  [[nodiscard]] long index(int a) const { return index_[a]; }
  // Whether the current voxel has an OctoMap key (every axis InKeyRange).
  [[nodiscard]] bool InsideKeyRange() const {
    return InKeyRange(index_[0]) && InKeyRange(index_[1]) && InKeyRange(index_[2]);
  }
  // The current voxel's key; only valid InsideKeyRange().
  [[nodiscard]] octomap::OcTreeKey Key() const {
    return octomap::OcTreeKey(static_cast<octomap::key_type>(index_[0] + kMapKeyOffset),
                              static_cast<octomap::key_type>(index_[1] + kMapKeyOffset),
                              static_cast<octomap::key_type>(index_[2] + kMapKeyOffset));
  }
  // Range where the ray entered the first voxel (the one holding p(t_first)); at most t_first,
  // -infinity for a zero direction.
  [[nodiscard]] double EntryRange() const { return entry_; }
  // The axis whose face the ray leaves the current voxel through (ties: the higher axis).
  [[nodiscard]] int NextAxis() const {
    return (t_max_[0] < t_max_[1]) ? (t_max_[0] < t_max_[2] ? 0 : 2)
                                   : (t_max_[1] < t_max_[2] ? 1 : 2);
  }
  // Range where the ray leaves the current voxel through the face of `axis`.
  [[nodiscard]] double ExitRange(int axis) const { return t_max_[axis]; }
  // Moves into the neighbour across `axis` (NextAxis()). Returns false if that voxel has no
  // key (its index left the key range): the ray has reached the map's edge and must stop.
  bool Step(int axis) {
    index_[axis] += step_[axis];
    t_max_[axis] += t_delta_[axis];
    return InKeyRange(index_[axis]);
  }

 private:
  long index_[3];
  int step_[3];
  double t_max_[3];    // range of the next face crossing on each axis
  double t_delta_[3];  // range between face crossings on each axis
  double entry_ = -std::numeric_limits<double>::infinity();
};

// Calls visit(traversal) for every voxel the ray crosses from t_first to t_end, in order: the
// voxel holding p(t_first) first, the one holding p(t_end) last. A ray that starts outside the
// key range visits nothing; one that leaves it stops at the map's edge (as the renderer does).
template <typename Visit>
void ForEachVoxel(const Eigen::Vector3d& origin, const Eigen::Vector3d& dir, double t_first,
                  double t_end, double resolution_m, Visit&& visit) {
  VoxelTraversal walk(origin, dir, t_first, resolution_m);
  if (!walk.InsideKeyRange()) return;
  while (true) {
    visit(static_cast<const VoxelTraversal&>(walk));
    const int axis = walk.NextAxis();
    if (walk.ExitRange(axis) >= t_end) return;  // this voxel holds the end
    if (!walk.Step(axis)) return;
  }
}

}  // namespace fusion
