// Internal to core (the projective render): the buffers a render reuses (RenderScratch).
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <vector>

#include "fusion/core/beam_grid.h"
#include "fusion/core/local_grid.h"
#include "fusion/core/projective_render.h"
#include "fusion/core/rendered_grid.h"
#include "projective_descent.h"

namespace fusion {

struct RenderScratch::Buffers {
  std::vector<BeamProfile> profiles;
  detail::BeamPyramid pyramid;    // level 0: each beam's Aggregate
  std::vector<LocalGrid> traced;  // one per tracing thread; [0] holds them all at the end
  detail::DescentBuffers descent;
  std::vector<MapNode> nodes;  // a spent result's storage (RenderScratch::Recycle)
};

}  // namespace fusion
