// Internal to core: tracing a beam's rays through the voxels of a world-frame grid, with each
// crossing's evidence from the beam's interval occupancy. Shared by the ray-traced render (every
// beam from r_min on) and the projective render (only through each beam's first-hit mass), so
// that both give a crossed voxel exactly the same segments.
//
// A beam is traced along its centre line, and with k_u x k_v sub-rays spread over its spherical
// sector where one line does not cover it: where the sector outgrows a voxel (beyond
// r_split = resolution / beam width), and where the surface it sees runs on into a neighbouring
// beam's (RenderOptions::follow_surfaces): a sub-ray then carries the beam's first-hit
// distribution shifted to the range interpolated between the two beams' surfaces, so a floor
// seen at a shallow angle is continuous between the rows of beams instead of striped.
#pragma once

#include <octomap/OcTree.h>

#include <Eigen/Geometry>
#include <cstddef>
#include <functional>
#include <limits>
#include <vector>

#include "fusion/core/beam_grid.h"
#include "fusion/core/local_grid.h"

namespace fusion::detail {

// The voxel rule's first step (docs/mapping.md, "From first-hit mass to evidence"): the evidence
// (log-odds, before the clamp) of one crossing of a beam, from the beam's hazard over it,
// hazard = P(first hit in the crossing | the beam reaches it) (telescoped Eq. 8), the beam
// prior's log-odds over the crossing's length, and reach = P(the beam reaches the crossing)
// (the first-hit mass left at its entry, relative to where the trace started).
// - hazard below the prior: free evidence, logit(hazard) - prior_log_odds, as before.
// - hazard between the prior and 1/2: none. The reading makes a surface there likelier than
//   the prior did, but the beam still more likely passes through than stops there: the voxel
//   stays as unknown as it was (a wide first-hit distribution's flanks).
// - hazard above 1/2: occupied evidence logit(hazard) (against the map's unknown 1/2), times
//   reach: behind the mass of a wide distribution Eq. 8's hazard tends to 1 while the beam
//   hardly ever gets there, and such a crossing says next to nothing. Of one ray's crossings
//   only the one holding most of its first-hit mass keeps it (BeamTracer::Trace).
[[nodiscard]] double SegmentEvidence(double hazard, double prior_log_odds, double reach);

// One voxel crossing of a ray with its evidence.
struct Segment {
  octomap::OcTreeKey key;
  float evidence;  // SegmentEvidence, clamped
  float weight;    // crossing length (metres) times the ray's weight
  double t_out_m;  // range where the ray leaves the voxel
};

// What tracing a beam did.
struct BeamTrace {
  std::size_t rays = 0;
  // The nearest a ray of the beam placed the start of its first-hit mass (the beam's
  // mass_begin_m moved by the sub-ray's shift); +infinity if no ray carried mass.
  double mass_begin_m = std::numeric_limits<double>::infinity();
};

// Every touched beam's profile from `t_start` (BeamGrid::Profile), untouched ones with
// mass_begin_m = +infinity and median_m = NaN; computed on `workers` threads.
// Into *profiles (its memory reused).
void ProfileBeams(const BeamGrid& grid, const RenderOptions& options, double t_start,
                  std::size_t workers, std::vector<BeamProfile>* profiles);
[[nodiscard]] std::vector<BeamProfile> ProfileBeams(const BeamGrid& grid,
                                                    const RenderOptions& options, double t_start,
                                                    std::size_t workers);

// Traces the beams of one grid seen from one pose. Not thread-safe: one per thread.
class BeamTracer {
 public:
  // profiles: ProfileBeams(grid, options, t_start(), ...), shared by every tracer of a render.
  BeamTracer(const BeamGrid& grid, const Eigen::Isometry3d& T_world_sensor,
             const RenderOptions& options, const std::vector<BeamProfile>& profiles);

  // Start of every ray (r_min, at least 0) and the end of the render (beam length, max range).
  [[nodiscard]] double t_start() const { return t_start_; }
  [[nodiscard]] double t_end() const { return t_end_; }

  // Appends the segments of beam b (touched) to *out. With first_mass_only, a ray enters no
  // voxel it leaves before the start of its first-hit mass: the voxel holding that start is
  // crossed whole (from where the ray enters it, or t_start()), and the evidence of every
  // crossing, and where each ray stops, are what the whole trace gives.
  BeamTrace TraceBeam(std::size_t beam, bool first_mass_only, std::vector<Segment>* out);

  [[nodiscard]] static double StartOf(const BeamGrid& grid) {
    return std::max(0.0, grid.spec().r_min_m);
  }

 private:
  // One ray from t_ref (the start its information is measured from) to t_end, entering no
  // voxel that it leaves before t_first; `shift` moves the beam's first-hit distribution along
  // the ray (range t reads the distribution at t - shift). Returns where it stopped.
  double Trace(std::size_t beam, const Eigen::Vector3d& dir, double t_ref, double t_first,
               double shift, float weight_scale, std::vector<Segment>* out, double info_end_m);
  // Where the centre ray enters the voxel that holds range r (not before t_start()).
  double VoxelEntry(const Eigen::Vector3d& dir, double r) const;
  // Range change from beam b's surface to the neighbour's, 0 if the neighbour sees another
  // surface (a depth edge) or none. `opposite`: the beam on b's other side along the same axis
  // (-1: none), whose step into b tells a surface at grazing incidence from an edge.
  double SurfaceStep(std::size_t beam, long neighbour, long opposite, double spacing_rad) const;
  // The four steps (0 where no surface is followed) of beam b.
  void SurfaceSteps(std::size_t beam, const BeamProfile& profile, double* left, double* right,
                    double* up, double* down) const;
  // The beam prior over n cells (BeamGrid::PriorOccupancy), and its log-odds; cached.
  struct Prior {
    double probability;
    double log_odds;
  };
  const Prior& PriorOfCells(long n);  // cached per tracer
  const Prior& FillPrior(std::size_t index);
  // IntervalOccupancy and InformationEndM of the beam being traced, read from table_ where it
  // covers the cells asked for (the same walk's numbers, so the same results).
  void Occupancies(std::size_t beam, const std::vector<double>& boundaries_m,
                   std::vector<double>* out);
  double InformationEnd(std::size_t beam, double from_m);
  // Fills table_ with S over the stretch of beam b that its rays read when they trace only the
  // first-hit mass (profile.mass_begin_m on), sub-rays shifted by up to reach_m included.
  void TabulateMass(std::size_t beam, const BeamProfile& profile, double reach_m);

  // S over one stretch of the beam being traced (BeamGrid::TailMassSpan).
  struct Table {
    std::size_t beam = 0;
    bool valid = false;
    std::uint32_t first = 0, last = 0;
    double total = 0.0;
    std::vector<double> tails;
    [[nodiscard]] bool Covers(std::size_t b, std::uint32_t lo, std::uint32_t hi) const {
      return valid && b == beam && lo >= first && hi <= last;
    }
    [[nodiscard]] double S(std::uint32_t c) const { return tails[c - first]; }
  };

  const BeamGrid& grid_;
  const RenderOptions& options_;
  const std::vector<BeamProfile>& profiles_;
  Eigen::Matrix3d R_;
  Eigen::Vector3d origin_;
  double t_start_;
  double t_end_;
  double width_rad_;
  double cell_m_;
  std::size_t cells_per_beam_;  // N, as BeamGrid::CellOf clamps to
  double inv_res_;     // as VoxelTraversal floors a point's index
  double continuity_;  // tan of the shallowest incidence still followed across beams, inverted
  std::vector<Prior> prior_cache_;
  std::vector<double> boundaries_;
  std::vector<octomap::OcTreeKey> keys_;
  std::vector<double> occupancy_;
  std::vector<std::uint32_t> cells_;
  std::vector<double> tails_;  // S at cells_ (Occupancies)
  Table table_;
};

// Workers for a render of `rows` beam rows with RenderOptions::threads = threads (0: one per
// hardware thread), at most one per block of rows.
[[nodiscard]] std::size_t RowWorkers(std::size_t rows, unsigned threads);
// Runs work(worker) for workers 0 .. workers - 1, worker 0 on the calling thread, the others on
// threads of their own; rethrows the first exception once all are done.
void RunWorkers(std::size_t workers, const std::function<void(std::size_t)>& work);
// Deals the rows to `workers` workers in blocks (so that every worker gets its share of near
// and far beams) and runs work(worker, rows) on each, worker 0 on the calling thread; rethrows
// the first exception.
void ForEachRowBlock(std::size_t rows, std::size_t workers,
                     const std::function<void(std::size_t, const std::vector<std::size_t>&)>& work);

}  // namespace fusion::detail
