// The projective render (docs/mapping.md): each beam's rays traced only through its first-hit
// mass (beam_trace.cc), then the octree visited top down against a pyramid of the beams
// (beam_pyramid.h, projective_descent.cc), free and unknown space decided block by block.
#include "fusion/core/projective_render.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

#include "beam_pyramid.h"
#include "beam_trace.h"
#include "projective_descent.h"
#include "render_scratch.h"

namespace fusion {
namespace {

using detail::Aggregate;

// One touched beam: its rays traced through its first-hit mass into *part, and what the pyramid
// keeps of it. clamp: RenderOptions::max_abs_log_odds.
Aggregate TraceBeamMass(std::size_t beam, const BeamProfile& profile, float clamp,
                        detail::BeamTracer* tracer, std::vector<detail::Segment>* segments,
                        LocalGrid* part, RenderStats* stats) {
  double free_end = std::min(profile.mass_begin_m, tracer->t_end());
  segments->clear();
  if (free_end < tracer->t_end()) {
    const detail::BeamTrace trace = tracer->TraceBeam(beam, /*first_mass_only=*/true, segments);
    stats->rays_traced += trace.rays;
    free_end = std::max(tracer->t_start(), std::min(free_end, trace.mass_begin_m));
  }
  double far = free_end;
  for (const auto& seg : *segments) {
    far = std::max(far, seg.t_out_m);
    part->AddEvidence(seg.key, seg.evidence, seg.weight);
  }
  stats->segments += segments->size();
  Aggregate a;
  a.beams = 1;
  a.touched = 1;
  a.min_free_end = a.max_free_end = static_cast<float>(free_end);
  a.max_far = static_cast<float>(far);
  a.max_free_value = std::isfinite(profile.free_log_odds)
                         ? std::clamp(static_cast<float>(profile.free_log_odds), -clamp, clamp)
                         : -clamp;
  return a;
}

// The rectangle of beams holding every touched one, found from the grid's edges inwards.
detail::BeamExtent TouchedExtent(const BeamGrid& grid) {
  const BeamTessellation& tess = grid.tessellation();
  const int cols = tess.cols(), rows = tess.rows();
  const auto touched = [&](int c, int r) {
    return grid.Touched(static_cast<std::size_t>(r) * static_cast<std::size_t>(cols) +
                        static_cast<std::size_t>(c));
  };
  detail::BeamExtent e{0, cols - 1, 0, rows - 1};
  const auto row_touched = [&](int r) {
    for (int c = 0; c < cols; ++c) {
      if (touched(c, r)) return true;
    }
    return false;
  };
  while (e.row_lo < rows && !row_touched(e.row_lo)) ++e.row_lo;
  if (e.row_lo == rows) return {};
  while (!row_touched(e.row_hi)) --e.row_hi;
  const auto column_touched = [&](int c) {
    for (int r = e.row_lo; r <= e.row_hi; ++r) {
      if (touched(c, r)) return true;
    }
    return false;
  };
  while (!column_touched(e.col_lo)) ++e.col_lo;
  while (!column_touched(e.col_hi)) --e.col_hi;
  return e;
}

// Every beam's rays through its first-hit mass, rows dealt to `workers` threads, each into its
// own grid of *traced (merged into (*traced)[0] at the end; their memory reused); (*beams)[b]
// becomes beam b's Aggregate. Returns the counters of that work.
RenderStats TraceMasses(const BeamGrid& grid, const Eigen::Isometry3d& T_world_sensor,
                        const RenderOptions& options, const std::vector<BeamProfile>& profiles,
                        std::size_t workers, const detail::BeamExtent& extent,
                        std::vector<LocalGrid>* traced, std::vector<Aggregate>* beams) {
  const auto rows = static_cast<std::size_t>(grid.tessellation().rows());
  const auto cols = static_cast<std::size_t>(grid.tessellation().cols());
  std::vector<LocalGrid>& parts = *traced;
  const auto alike = [&options](const LocalGrid& g) {
    return g.resolution_m() == options.resolution_m && g.combine() == options.combine;
  };
  if (parts.size() < workers || !std::all_of(parts.begin(), parts.end(), alike)) {
    parts.assign(workers, LocalGrid(options.resolution_m, options.combine));
  }
  std::vector<RenderStats> part_stats(workers);
  const float clamp = static_cast<float>(options.max_abs_log_odds);
  detail::ForEachRowBlock(rows, workers, [&](std::size_t t, const std::vector<std::size_t>& mine) {
    detail::BeamTracer tracer(grid, T_world_sensor, options, profiles);
    std::vector<detail::Segment> segments;
    RenderStats& s = part_stats[t];
    // A beam's mass crosses a voxel or two; fine grids' beams share voxels (a 640 x 480 stereo
    // frame: 15.6 k voxels from 307 k beams): a table for every beam would cost more to clear.
    parts[t].Clear();
    parts[t].Reserve(mine.size() * cols / 8 + 1024);
    for (const std::size_t row : mine) {
      for (std::size_t b = row * cols; b < (row + 1) * cols; ++b) {
        if (!grid.Touched(b)) {
          const int col = static_cast<int>(b - row * cols);
          (*beams)[b].beams = extent.Holds(col, static_cast<int>(row)) ? 1 : 0;
          ++s.beams_untouched;
          continue;
        }
        ++s.beams_rendered;
        (*beams)[b] = TraceBeamMass(b, profiles[b], clamp, &tracer, &segments, &parts[t], &s);
      }
    }
  });
  RenderStats out = part_stats[0];
  for (std::size_t t = 1; t < workers; ++t) {
    parts[0].Merge(parts[t]);
    out.beams_rendered += part_stats[t].beams_rendered;
    out.beams_untouched += part_stats[t].beams_untouched;
    out.rays_traced += part_stats[t].rays_traced;
    out.segments += part_stats[t].segments;
  }
  out.voxels = parts[0].size();
  return out;
}

}  // namespace

RenderScratch::RenderScratch() : buffers_(std::make_unique<Buffers>()) {}
RenderScratch::~RenderScratch() = default;
RenderScratch::RenderScratch(RenderScratch&&) noexcept = default;
RenderScratch& RenderScratch::operator=(RenderScratch&&) noexcept = default;

void RenderScratch::Recycle(RenderedGrid&& spent) {
  std::vector<MapNode> storage = spent.TakeStorage();
  if (storage.capacity() > buffers_->nodes.capacity()) buffers_->nodes = std::move(storage);
}

std::size_t RenderScratch::MemoryBytes() const {
  const Buffers& b = *buffers_;
  std::size_t bytes = sizeof(Buffers) + b.profiles.capacity() * sizeof(BeamProfile) +
                      b.pyramid.MemoryBytes() + b.descent.MemoryBytes() +
                      b.nodes.capacity() * sizeof(MapNode);
  for (const LocalGrid& g : b.traced) bytes += g.MemoryBytes();
  return bytes;
}

RenderedGrid RenderProjective(const BeamGrid& grid, const Eigen::Isometry3d& T_world_sensor,
                              const RenderOptions& options, RenderStats* stats,
                              const SaturatedFree* skip, RenderScratch* scratch) {
  const BeamTessellation& tess = grid.tessellation();
  // The mean and the pool of a voxel's segments need every crossing of every ray, free ones
  // included: only the max rule lets the free zones be decided block by block.
  if (!tess.HasTangentEdges() || options.combine != VoxelCombine::kMaxLogOdds) {
    return RenderedGrid::FromLocalGrid(RenderBeamGrid(grid, T_world_sensor, options, stats));
  }
  RenderScratch own;  // used when the caller keeps none: everything freshly allocated
  RenderScratch::Buffers& buffers = (scratch != nullptr ? scratch : &own)->buffers();
  const std::size_t workers =
      detail::RowWorkers(static_cast<std::size_t>(tess.rows()), options.threads);
  const double t_start = detail::BeamTracer::StartOf(grid);
  // Each beam's free zone and mass (first, for every beam: a beam's rays follow its
  // neighbours' surfaces), then its rays traced through the mass.
  detail::ProfileBeams(grid, options, t_start, workers, &buffers.profiles);
  std::vector<Aggregate>& beams = buffers.pyramid.Beams(tess.cols(), tess.rows());
  const detail::BeamExtent extent = TouchedExtent(grid);
  buffers.pyramid.SetTouchedExtent(extent);
  RenderStats s = TraceMasses(grid, T_world_sensor, options, buffers.profiles, workers, extent,
                              &buffers.traced, &beams);
  float global_far = -std::numeric_limits<float>::infinity();
  for (const Aggregate& a : beams) global_far = std::max(global_far, a.max_far);
  buffers.pyramid.Build();
  RenderedGrid out(options.resolution_m, std::move(buffers.nodes));
  buffers.nodes = {};
  if (s.beams_rendered > 0) {
    detail::DescendOctree(grid, T_world_sensor, options, buffers.pyramid, buffers.traced[0],
                          t_start, global_far, skip, workers, &buffers.descent, &out, &s);
  }
  if (stats != nullptr) *stats = s;
  return out;
}

RenderedGrid Render(const BeamGrid& grid, const Eigen::Isometry3d& T_world_sensor,
                    const RenderOptions& options, RenderStats* stats, const SaturatedFree* skip,
                    RenderScratch* scratch) {
  if (options.method == RenderMethod::kRayTraced) {
    return RenderedGrid::FromLocalGrid(RenderBeamGrid(grid, T_world_sensor, options, stats));
  }
  return RenderProjective(grid, T_world_sensor, options, stats, skip, scratch);
}

}  // namespace fusion
