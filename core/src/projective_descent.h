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
  // A descent thread's own: the beams' centre lines in the world frame, each computed when
  // first needed.
  struct Directions {
    std::vector<Eigen::Vector3f> directions;
    std::vector<std::uint8_t> have;
  };
  std::vector<Directions> directions;         // one per descent thread
  std::vector<std::uint64_t> occupied_codes;  // traced voxels with occupied evidence, ascending
  // With several threads: each thread's nodes, and (last) the nodes decided above the blocks
  // they share out.
  std::vector<std::vector<MapNode>> nodes;
  [[nodiscard]] std::size_t MemoryBytes() const {
    std::size_t bytes = occupied_codes.capacity() * sizeof(std::uint64_t);
    for (const Directions& d : directions) {
      bytes += d.directions.capacity() * sizeof(Eigen::Vector3f) + d.have.capacity();
    }
    for (const auto& n : nodes) bytes += n.capacity() * sizeof(MapNode);
    return bytes;
  }
};

// Visits the octree top down from its root and appends every decided node (free blocks whole,
// traced and free voxels) to *out, counting them in *stats. pyramid: every beam's Aggregate;
// traced: the voxels the rays crossed in the beams' first-hit mass; t_start: where every ray
// starts; global_far: the largest Aggregate::max_far; skip: the map's saturated free space to
// leave out (may be null). With workers > 1 the blocks of kShareDepth that need a closer look
// are shared out among that many threads (worker 0 the caller); the nodes are the same.
void DescendOctree(const BeamGrid& grid, const Eigen::Isometry3d& T_world_sensor,
                   const RenderOptions& options, const BeamPyramid& pyramid,
                   const LocalGrid& traced, double t_start, float global_far,
                   const SaturatedFree* skip, std::size_t workers, DescentBuffers* buffers,
                   RenderedGrid* out, RenderStats* stats);

// The depth of the blocks a descent on several threads shares out (16 voxels on a side: a
// render's mixed blocks at that depth number in the hundreds to thousands).
inline constexpr unsigned kShareDepth = 12;

}  // namespace fusion::detail
