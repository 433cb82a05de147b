// The projective, multi-resolution render of a beam grid (docs/mapping.md, "Projective
// render"): the map's octree is visited top-down over the sensor's frustum; a block is decided
// whole when a pyramid over the beams says it lies wholly in front of the first-hit mass of every
// beam it overlaps (free, one coarse node) or reaches no beam's information (unknown, nothing);
// only blocks that straddle first-hit mass are split, down to voxels, and the rays of a beam
// are traced only through its mass, where they give exactly what the ray-traced render gives.
#pragma once

#include <Eigen/Geometry>
#include <cstddef>
#include <memory>
#include <vector>

#include "fusion/core/beam_grid.h"
#include "fusion/core/local_grid.h"
#include "fusion/core/rendered_grid.h"

namespace fusion {

// What the map already holds saturated free: leaves of the committed history at or below the
// free clamp, where no other live contribution has a node. A part of the render that would come
// out with evidence <= 0 there is left out: under Eq. 16 (log-odds add, then the clamp) such
// evidence cannot move a value held at the free clamp, so the fused map is the same without it
// (exactly: the parts other sensors' live contributions cover are never left out). For a moving
// sensor most of each frame's free space was seen, and saturated, by the frames before.
struct SaturatedFree {
  const octomap::OcTree* history = nullptr;
  float clamp_min_log_odds = 0.0f;
  std::vector<const RenderedGrid*> others;  // at most 8
};

// What a render can reuse from the renders before it: the beams' profiles and pyramid, the
// voxels traced, the result's node storage (Recycle). Renders of one sensor are much alike in
// size, and memory freshly mapped for each of them can cost as much as the render's own work
// (BENCHMARKS.md, "Render buffers reused"). Not thread-safe: one per thread that renders.
class RenderScratch {
 public:
  RenderScratch();
  ~RenderScratch();
  RenderScratch(RenderScratch&&) noexcept;
  RenderScratch& operator=(RenderScratch&&) noexcept;

  // Keeps a spent render's node storage for the next render's result.
  void Recycle(RenderedGrid&& spent);
  [[nodiscard]] std::size_t MemoryBytes() const;

  struct Buffers;  // core's own (render_scratch.h)
  [[nodiscard]] Buffers& buffers() { return *buffers_; }

 private:
  std::unique_ptr<Buffers> buffers_;
};

// Same inputs and frames as RenderBeamGrid (the oracle); the result holds coarse free blocks
// and voxels, in Morton order. Sensors whose field of view reaches 180 degrees on either axis
// are rendered ray by ray (the pyramid needs the tangent tables), and so are the voxel rules
// other than the max (the mean and the pool of a voxel's segments need every crossing of every
// ray, free ones included). `skip` (may be null): see SaturatedFree.
[[nodiscard]] RenderedGrid RenderProjective(const BeamGrid& grid,
                                            const Eigen::Isometry3d& T_world_sensor,
                                            const RenderOptions& options,
                                            RenderStats* stats = nullptr,
                                            const SaturatedFree* skip = nullptr,
                                            RenderScratch* scratch = nullptr);

// options.method's render: RenderProjective, or RenderBeamGrid as a RenderedGrid of voxels.
// `scratch` (may be null): buffers reused from the renders before.
[[nodiscard]] RenderedGrid Render(const BeamGrid& grid, const Eigen::Isometry3d& T_world_sensor,
                                  const RenderOptions& options, RenderStats* stats = nullptr,
                                  const SaturatedFree* skip = nullptr,
                                  RenderScratch* scratch = nullptr);

}  // namespace fusion
