#include "beam_trace.h"

#include <algorithm>
#include <cmath>
#include <exception>
#include <limits>
#include <thread>

namespace fusion::detail {
namespace {

constexpr int kTreeMaxVal = 32768;  // octomap tree_max_val for depth 16
constexpr std::size_t kChunkSegments = 256;
constexpr std::size_t kRowsPerBlock = 4;
constexpr double kProbabilityFloor = 1e-9;

double Logit(double p) {
  p = std::clamp(p, kProbabilityFloor, 1.0 - kProbabilityFloor);
  return std::log(p / (1.0 - p));
}

}  // namespace

BeamTracer::BeamTracer(const BeamGrid& grid, const Eigen::Isometry3d& T_world_sensor,
                       const RenderOptions& options)
    : grid_(grid),
      options_(options),
      R_(T_world_sensor.linear()),
      origin_(T_world_sensor.translation()),
      t_start_(std::max(0.0, grid.spec().r_min_m)),
      t_end_(std::min(static_cast<double>(grid.cells_per_beam()) * grid.options().cell_size_m,
                      options.max_range_m)),
      width_rad_(std::max(grid.tessellation().beam_width_h_rad(),
                          grid.tessellation().beam_width_v_rad())),
      cell_m_(grid.options().cell_size_m),
      inv_res_(1.0 / options.resolution_m) {
  boundaries_.reserve(kChunkSegments + 1);
  keys_.reserve(kChunkSegments);
}

double BeamTracer::PriorLogOddsOfCells(long n) {
  const auto index = static_cast<std::size_t>(std::max(n, 0L));
  if (index >= prior_cache_.size()) {
    prior_cache_.resize(index + 1, std::numeric_limits<double>::quiet_NaN());
  }
  double& v = prior_cache_[index];
  if (std::isnan(v)) v = Logit(grid_.PriorOccupancy(static_cast<double>(index) * cell_m_));
  return v;
}

double BeamTracer::Trace(std::size_t beam, const Eigen::Vector3d& dir, double t_ref,
                         double t_first, float weight_scale, std::vector<Segment>* out,
                         double info_end_m) {
  if (!(t_end_ > t_ref)) return t_ref;
  // Voxels beyond the cell where the remaining first-hit mass falls below tail_mass are never
  // reached: the loop below stops there. Entering no voxel past that cell saves the traversal
  // and the interval lookups of a whole chunk behind every surface; the voxel holding the cell
  // is still crossed whole.
  if (std::isnan(info_end_m)) info_end_m = grid_.InformationEndM(beam, t_ref, options_.tail_mass);
  const double t_last_entry = std::min(t_end_, info_end_m + cell_m_);
  t_first = std::max(t_first, t_ref);
  if (t_first >= t_last_entry) return t_last_entry;
  const double res = options_.resolution_m;
  const Eigen::Vector3d p0 = origin_ + dir * t_first;
  long index[3];
  int step[3];
  double t_max[3];
  double t_delta[3];
  double t_entry = t_ref;  // where the ray enters the voxel holding p0 (not before t_ref)
  for (int a = 0; a < 3; ++a) {
    index[a] = static_cast<long>(std::floor(p0[a] * inv_res_));
    if (dir[a] > 0.0) {
      step[a] = 1;
      t_max[a] = t_first + ((index[a] + 1) * res - p0[a]) / dir[a];
      t_delta[a] = res / dir[a];
      t_entry = std::max(t_entry, t_first + (index[a] * res - p0[a]) / dir[a]);
    } else if (dir[a] < 0.0) {
      step[a] = -1;
      t_max[a] = t_first + (index[a] * res - p0[a]) / dir[a];
      t_delta[a] = -res / dir[a];
      t_entry = std::max(t_entry, t_first + ((index[a] + 1) * res - p0[a]) / dir[a]);
    } else {
      step[a] = 0;
      t_max[a] = std::numeric_limits<double>::infinity();
      t_delta[a] = std::numeric_limits<double>::infinity();
    }
  }
  double t_in = std::min(t_entry, t_first);
  // The mass the ray has left behind it since t_ref, as a trace from t_ref would have counted it.
  double remaining_mass = 1.0;
  if (t_in > t_ref) {
    boundaries_.assign({t_ref, t_in});
    grid_.IntervalOccupancy(beam, boundaries_, &occupancy_);
    remaining_mass = 1.0 - occupancy_[0];
    if (remaining_mass < options_.tail_mass) return t_in;
  }
  bool done = false;
  while (!done) {
    boundaries_.clear();
    keys_.clear();
    boundaries_.push_back(t_in);
    while (keys_.size() < kChunkSegments && t_in < t_last_entry) {
      const int axis =
          (t_max[0] < t_max[1]) ? (t_max[0] < t_max[2] ? 0 : 2) : (t_max[1] < t_max[2] ? 1 : 2);
      const double t_out = std::min(t_max[axis], t_end_);
      keys_.emplace_back(static_cast<octomap::key_type>(index[0] + kTreeMaxVal),
                         static_cast<octomap::key_type>(index[1] + kTreeMaxVal),
                         static_cast<octomap::key_type>(index[2] + kTreeMaxVal));
      boundaries_.push_back(t_out);
      t_in = t_out;
      index[axis] += step[axis];
      t_max[axis] += t_delta[axis];
    }
    if (keys_.empty()) break;
    grid_.IntervalOccupancy(beam, boundaries_, &occupancy_);
    long c1 = std::lround(boundaries_[0] / cell_m_);
    for (std::size_t j = 0; j < keys_.size(); ++j) {
      const long c0 = c1;
      c1 = std::lround(boundaries_[j + 1] / cell_m_);
      if (c1 <= c0) continue;  // shorter than a beam cell: no evidence of its own
      const double p = j < occupancy_.size() ? occupancy_[j] : 0.5;
      double evidence = Logit(p) - PriorLogOddsOfCells(c1 - c0);
      evidence = std::clamp(evidence, -options_.max_abs_log_odds, options_.max_abs_log_odds);
      const double length_m = boundaries_[j + 1] - boundaries_[j];
      out->push_back({keys_[j], static_cast<float>(evidence),
                      static_cast<float>(length_m) * weight_scale, boundaries_[j + 1]});
      remaining_mass *= (1.0 - p);
      if (remaining_mass < options_.tail_mass) {
        done = true;
        t_in = boundaries_[j + 1];
        break;
      }
    }
    if (t_in >= t_last_entry) done = true;
  }
  return t_in;
}

std::size_t BeamTracer::TraceBeam(std::size_t beam, double first_m, std::vector<Segment>* out,
                                  double info_end_m) {
  const BeamTessellation& tess = grid_.tessellation();
  const Eigen::Vector3d dir_sensor = tess.Direction(beam);
  const Eigen::Vector3d dir = R_ * dir_sensor;
  const std::size_t kept_from = out->size();
  const double t_stop = Trace(beam, dir, t_start_, first_m, 1.0f, out, info_end_m);
  const int k = std::clamp(static_cast<int>(std::ceil(width_rad_ * t_stop / options_.resolution_m)),
                           1, std::max(1, options_.max_subrays_per_axis));
  if (k == 1) return 1;
  // The beam's footprint outgrows a voxel at r_split = resolution / width: keep the centre ray
  // up to the voxel boundary before r_split and spread k x k sub-rays uniformly over its
  // azimuth x elevation sector beyond, each with weight 1 / k^2.
  const double r_split = options_.resolution_m / width_rad_;
  double t_sub = t_start_;
  if (r_split > t_start_) {
    // Where the centre ray enters the voxel holding r_split.
    const Eigen::Vector3d p = origin_ + dir * r_split;
    for (int a = 0; a < 3; ++a) {
      if (dir[a] == 0.0) continue;
      const double lo = std::floor(p[a] * inv_res_) * options_.resolution_m;
      const double face = dir[a] > 0.0 ? lo : lo + options_.resolution_m;
      t_sub = std::max(t_sub, r_split + (face - p[a]) / dir[a]);
    }
    t_sub = std::min(t_sub, r_split);
  }
  std::size_t keep = kept_from;
  while (keep < out->size() && (*out)[keep].t_out_m <= t_sub) ++keep;
  out->resize(keep);
  // Every sub-ray starts at t_sub: their information end is shared.
  const double sub_info_end_m =
      t_sub == t_start_ && !std::isnan(info_end_m)
          ? info_end_m
          : grid_.InformationEndM(beam, t_sub, options_.tail_mass);
  const double az = std::atan2(dir_sensor.x(), dir_sensor.z());
  const double el = std::atan2(-dir_sensor.y(), std::hypot(dir_sensor.x(), dir_sensor.z()));
  const float weight = 1.0f / static_cast<float>(k * k);
  for (int i = 0; i < k; ++i) {
    const double sub_az = az + ((i + 0.5) / k - 0.5) * tess.beam_width_h_rad();
    for (int j = 0; j < k; ++j) {
      const double sub_el = el + ((j + 0.5) / k - 0.5) * tess.beam_width_v_rad();
      const Eigen::Vector3d d(std::cos(sub_el) * std::sin(sub_az), -std::sin(sub_el),
                              std::cos(sub_el) * std::cos(sub_az));
      Trace(beam, R_ * d, t_sub, first_m, weight, out, sub_info_end_m);
    }
  }
  return 1 + static_cast<std::size_t>(k * k);
}

std::size_t RowWorkers(std::size_t rows, unsigned threads) {
  const std::size_t n = threads != 0 ? threads : std::max(1u, std::thread::hardware_concurrency());
  return std::clamp<std::size_t>(n, 1, std::max<std::size_t>(1, rows / kRowsPerBlock));
}

void ForEachRowBlock(
    std::size_t rows, std::size_t n,
    const std::function<void(std::size_t, const std::vector<std::size_t>&)>& work) {
  std::vector<std::vector<std::size_t>> rows_of(n);
  for (std::size_t r = 0; r < rows; ++r) rows_of[(r / kRowsPerBlock) % n].push_back(r);
  std::vector<std::exception_ptr> errors(n);
  const auto run = [&](std::size_t t) {
    try {
      work(t, rows_of[t]);
    } catch (...) {
      errors[t] = std::current_exception();
    }
  };
  std::vector<std::thread> helpers;
  for (std::size_t t = 1; t < n; ++t) helpers.emplace_back(run, t);
  run(0);
  for (std::thread& h : helpers) h.join();
  for (const auto& e : errors) {
    if (e) std::rethrow_exception(e);
  }
}

}  // namespace fusion::detail
