// Internal to core: tracing a beam's centre ray (and, where the beam is wider than a voxel, its
// sub-rays) through the voxels of a world-frame grid, with each crossing's evidence from the
// beam's interval occupancy. Shared by the ray-traced render (every beam from r_min on) and the
// projective render (only through each beam's first-hit mass), so that both give a crossed voxel
// exactly the same segments.
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

// One voxel crossing of a ray with its evidence.
struct Segment {
  octomap::OcTreeKey key;
  float evidence;  // log-odds relative to the prior of the crossing's length
  float weight;    // crossing length (metres) times the ray's weight
  double t_out_m;  // range where the ray leaves the voxel
};

// Traces the beams of one grid seen from one pose. Not thread-safe: one per thread.
class BeamTracer {
 public:
  BeamTracer(const BeamGrid& grid, const Eigen::Isometry3d& T_world_sensor,
             const RenderOptions& options);

  // Start of every ray (r_min, at least 0) and the end of the render (beam length, max range).
  [[nodiscard]] double t_start() const { return t_start_; }
  [[nodiscard]] double t_end() const { return t_end_; }

  // Appends the segments of beam b (touched) to *out: its centre ray from t_start(), and beyond
  // r_split = resolution / beam width its k x k sub-rays where the beam's footprint outgrows a
  // voxel (docs/mapping.md, "Beam width"). Only voxels a ray leaves after first_m are traced:
  // the voxel holding first_m is crossed whole (from where the ray enters it, or t_start()),
  // and the evidence of every crossing, and where each ray stops, are what a trace from
  // t_start() gives. first_m = t_start() traces the whole beam. info_end_m, if not NaN, is
  // BeamGrid::InformationEndM(beam, t_start(), tail_mass) known already. Returns the rays traced.
  std::size_t TraceBeam(std::size_t beam, double first_m, std::vector<Segment>* out,
                        double info_end_m = std::numeric_limits<double>::quiet_NaN());

 private:
  // One ray from t_ref (the start its information is measured from) to t_end, entering no
  // voxel that it leaves before t_first; returns where it stopped.
  double Trace(std::size_t beam, const Eigen::Vector3d& dir, double t_ref, double t_first,
               float weight_scale, std::vector<Segment>* out, double info_end_m);
  double PriorLogOddsOfCells(long n);

  const BeamGrid& grid_;
  const RenderOptions& options_;
  Eigen::Matrix3d R_;
  Eigen::Vector3d origin_;
  double t_start_;
  double t_end_;
  double width_rad_;
  double cell_m_;
  double inv_res_;
  std::vector<double> prior_cache_;
  std::vector<double> boundaries_;
  std::vector<octomap::OcTreeKey> keys_;
  std::vector<double> occupancy_;
};

// Workers for a render of `rows` beam rows with RenderOptions::threads = threads (0: one per
// hardware thread), at most one per block of rows.
[[nodiscard]] std::size_t RowWorkers(std::size_t rows, unsigned threads);
// Deals the rows to `workers` workers in blocks (so that every worker gets its share of near
// and far beams) and runs work(worker, rows) on each, worker 0 on the calling thread; rethrows
// the first exception.
void ForEachRowBlock(std::size_t rows, std::size_t workers,
                     const std::function<void(std::size_t, const std::vector<std::size_t>&)>& work);

}  // namespace fusion::detail
