// The projective, multi-resolution render of a beam grid (docs/mapping.md, "Projective
// render"): the map's octree is visited top-down over the sensor's frustum; a block is decided
// whole when a pyramid over the beams says it lies wholly in front of the first-hit mass of every
// beam it overlaps (free, one coarse node) or reaches no beam's information (unknown, nothing);
// only blocks that straddle first-hit mass are split, down to voxels, and the rays of a beam
// are traced only through its mass, where they give exactly what the ray-traced render gives.
#pragma once

#include <Eigen/Geometry>

#include "fusion/core/beam_grid.h"
#include "fusion/core/local_grid.h"
#include "fusion/core/rendered_grid.h"

namespace fusion {

// Same inputs and frames as RenderBeamGrid (the oracle); the result holds coarse free blocks
// and voxels, in Morton order. Sensors whose field of view reaches 180 degrees on either axis
// are rendered ray by ray (the pyramid needs the tangent tables).
[[nodiscard]] RenderedGrid RenderProjective(const BeamGrid& grid,
                                            const Eigen::Isometry3d& T_world_sensor,
                                            const RenderOptions& options,
                                            RenderStats* stats = nullptr);

// options.method's render: RenderProjective, or RenderBeamGrid as a RenderedGrid of voxels. The
// voxel rules other than the max (the mean and the pool of a voxel's segments) need every
// crossing of every ray, free ones included, and are always rendered ray by ray.
[[nodiscard]] RenderedGrid Render(const BeamGrid& grid, const Eigen::Isometry3d& T_world_sensor,
                                  const RenderOptions& options, RenderStats* stats = nullptr);

}  // namespace fusion
