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

// Visits the octree top down from its root and appends every decided node (free blocks whole,
// traced and free voxels) to *out, counting them in *stats. pyramid: every beam's Aggregate;
// traced: the voxels the rays crossed in the beams' first-hit mass; t_start: where every ray
// starts; global_far: the largest Aggregate::max_far; skip: the map's saturated free space to
// leave out (may be null); directions, have_direction: room for the beams' centre lines (their
// memory reused, their contents not).
void DescendOctree(const BeamGrid& grid, const Eigen::Isometry3d& T_world_sensor,
                   const RenderOptions& options, const BeamPyramid& pyramid,
                   const LocalGrid& traced, double t_start, float global_far,
                   const SaturatedFree* skip, std::vector<Eigen::Vector3f>* directions,
                   std::vector<std::uint8_t>* have_direction, RenderedGrid* out,
                   RenderStats* stats);

}  // namespace fusion::detail
