// Internal to core (the projective render): the buffers a render reuses (RenderScratch).
#pragma once

#include <Eigen/Core>

#include <cstdint>
#include <vector>

#include "beam_pyramid.h"
#include "fusion/core/beam_grid.h"
#include "fusion/core/local_grid.h"
#include "fusion/core/projective_render.h"
#include "fusion/core/rendered_grid.h"

namespace fusion {

struct RenderScratch::Buffers {
  std::vector<BeamProfile> profiles;
  detail::BeamPyramid pyramid;             // level 0: each beam's Aggregate
  std::vector<LocalGrid> traced;           // one per tracing thread; [0] holds them all at the end
  std::vector<Eigen::Vector3f> directions;  // beams' centre lines, world frame (the descent's)
  std::vector<std::uint8_t> have_direction;
  std::vector<MapNode> nodes;              // a spent result's storage (RenderScratch::Recycle)
};

}  // namespace fusion
