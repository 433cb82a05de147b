// Internal to core (the projective render): the top-down visit of the octree that decides
// blocks as free, unknown or mixed from the beam pyramid, emits the free ones whole and looks
// closer only at the mixed ones, down to the voxels the rays were traced through.
#pragma once

#include <Eigen/Geometry>
#include <cstdint>
#include <vector>

#include "beam_pyramid.h"
#include "fusion/core/beam_grid.h"
#include "fusion/core/local_grid.h"
#include "fusion/core/projective_render.h"
#include "fusion/core/rendered_grid.h"

namespace fusion::detail {

// Room a descent reuses from render to render (memory, not contents).
struct DescentBuffers {
  std::vector<Eigen::Vector3f> directions;  // beams' centre lines, world frame
  std::vector<std::uint8_t> have_direction;
  std::vector<std::uint64_t> occupied_codes;  // traced voxels with occupied evidence, ascending
  [[nodiscard]] std::size_t MemoryBytes() const {
    return directions.capacity() * sizeof(Eigen::Vector3f) + have_direction.capacity() +
           occupied_codes.capacity() * sizeof(std::uint64_t);
  }
};

// Visits the octree top down from its root and appends every decided node (free blocks whole,
// traced and free voxels) to *out, counting them in *stats. pyramid: every beam's Aggregate;
// traced: the voxels the rays crossed in the beams' first-hit mass; t_start: where every ray
// starts; global_far: the largest Aggregate::max_far; skip: the map's saturated free space to
// leave out (may be null).
void DescendOctree(const BeamGrid& grid, const Eigen::Isometry3d& T_world_sensor,
                   const RenderOptions& options, const BeamPyramid& pyramid,
                   const LocalGrid& traced, double t_start, float global_far,
                   const SaturatedFree* skip, DescentBuffers* buffers, RenderedGrid* out,
                   RenderStats* stats);

}  // namespace fusion::detail
