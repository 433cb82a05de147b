#include "beam_trace.h"

#include <algorithm>
#include <cmath>
#include <exception>
#include <limits>
#include <thread>

#include "fusion/core/voxel_traversal.h"

namespace fusion::detail {
namespace {

constexpr std::size_t kChunkSegments = 256;
constexpr std::size_t kRowsPerBlock = 4;
constexpr double kProbabilityFloor = 1e-9;
constexpr double kPi = 3.14159265358979323846;
// The longest stretch of a beam (cells) a tracer tabulates.
constexpr std::uint32_t kMaxTableCells = 8192;
// Beyond the shallowest incidence, a step into a neighbour still follows one surface when it
// differs from the step into the beam from its other side by at most this share of itself.
constexpr double kProgressionTolerance = 0.5;

double Logit(double p) {
  p = std::clamp(p, kProbabilityFloor, 1.0 - kProbabilityFloor);
  return std::log(p / (1.0 - p));
}

// std::lround, without its library call where x >= 0 (every crossing of a trace asks).
long NearestCell(double x) { return x >= 0.0 ? static_cast<long>(x + 0.5) : std::lround(x); }

// Offset of sub-ray i of k across a beam, in beam widths (-0.5, 0.5).
double SubOffset(int i, int k) { return (i + 0.5) / k - 0.5; }

// One ray's occupied evidence stays only in its crossing `mode` (the one holding the most of
// the ray's first-hit mass, reach times hazard, among those with occupied evidence); the other
// crossings of segments[first, end) with occupied evidence get 0, as the dead band's. Eq. 8's
// hazard tends to 1 at the far end of a wide distribution, and even weighted by reach it gave
// a voxel holding a fifth of the mass there 0.6 to 1 log-odds, against logit(0.6) = 0.4 for the
// voxel holding most of it: surfaces came out a voxel thick behind what the sensor saw.
void KeepOccupiedAtMode(std::size_t first, std::size_t mode, std::vector<Segment>* segments) {
  for (std::size_t i = first; i < segments->size(); ++i) {
    Segment& s = (*segments)[i];
    if (i != mode && s.evidence > 0.0f) s.evidence = 0.0f;
  }
}

// Shift of the first-hit distribution at offset f toward the neighbour steps (`minus` at
// f < 0, `plus` at f > 0): linear from the beam's centre to the neighbour's.
double ShiftAt(double f, double minus, double plus) { return f >= 0.0 ? f * plus : -f * minus; }

}  // namespace

std::vector<BeamProfile> ProfileBeams(const BeamGrid& grid, const RenderOptions& options,
                                      double t_start, std::size_t workers) {
  std::vector<BeamProfile> profiles;
  ProfileBeams(grid, options, t_start, workers, &profiles);
  return profiles;
}

void ProfileBeams(const BeamGrid& grid, const RenderOptions& options, double t_start,
                  std::size_t workers, std::vector<BeamProfile>* out) {
  constexpr double kInf = std::numeric_limits<double>::infinity();
  out->assign(grid.beam_count(), {kInf, kInf, -kInf, std::numeric_limits<double>::quiet_NaN()});
  std::vector<BeamProfile>& profiles = *out;
  const auto cols = static_cast<std::size_t>(grid.tessellation().cols());
  ForEachRowBlock(static_cast<std::size_t>(grid.tessellation().rows()), workers,
                  [&](std::size_t, const std::vector<std::size_t>& rows) {
                    for (const std::size_t row : rows) {
                      for (std::size_t b = row * cols; b < (row + 1) * cols; ++b) {
                        if (!grid.Touched(b)) continue;
                        profiles[b] =
                            grid.Profile(b, t_start, options.tail_mass, options.free_ratio);
                      }
                    }
                  });
}

BeamTracer::BeamTracer(const BeamGrid& grid, const Eigen::Isometry3d& T_world_sensor,
                       const RenderOptions& options, const std::vector<BeamProfile>& profiles)
    : grid_(grid),
      options_(options),
      profiles_(profiles),
      R_(T_world_sensor.linear()),
      origin_(T_world_sensor.translation()),
      t_start_(StartOf(grid)),
      t_end_(std::min(static_cast<double>(grid.cells_per_beam()) * grid.options().cell_size_m,
                      options.max_range_m)),
      width_rad_(
          std::max(grid.tessellation().beam_width_h_rad(), grid.tessellation().beam_width_v_rad())),
      cell_m_(grid.options().cell_size_m),
      cells_per_beam_(grid.cells_per_beam()),
      inv_res_(1.0 / options.resolution_m),
      continuity_(1.0 / std::tan(std::clamp(options.min_incidence_deg, 0.1, 89.0) * kPi / 180.0)) {
  boundaries_.reserve(kChunkSegments + 1);
  keys_.reserve(kChunkSegments);
}

double SegmentEvidence(double hazard, double prior_log_odds, double reach) {
  const double l = Logit(hazard);
  if (l <= prior_log_odds) return l - prior_log_odds;
  return reach * std::max(0.0, l - std::max(prior_log_odds, 0.0));
}

inline const BeamTracer::Prior& BeamTracer::PriorOfCells(long n) {
  const auto index = static_cast<std::size_t>(std::max(n, 0L));
  if (index < prior_cache_.size() && !std::isnan(prior_cache_[index].probability)) {
    return prior_cache_[index];
  }
  return FillPrior(index);
}

const BeamTracer::Prior& BeamTracer::FillPrior(std::size_t index) {
  constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
  if (index >= prior_cache_.size()) prior_cache_.resize(index + 1, Prior{kNaN, kNaN});
  Prior& v = prior_cache_[index];
  v.probability = grid_.PriorOccupancy(static_cast<double>(index) * cell_m_);
  v.log_odds = Logit(v.probability);
  return v;
}

double BeamTracer::Trace(std::size_t beam, const Eigen::Vector3d& dir, double t_ref, double t_first,
                         double shift, float weight_scale, std::vector<Segment>* out,
                         double info_end_m) {
  // The distribution is read at u = t - shift; its blind cells (u < r_min) never are.
  t_ref = std::max(t_ref, t_start_ + std::max(shift, 0.0));
  if (!(t_end_ > t_ref)) return t_ref;
  // Voxels beyond the cell where the remaining first-hit mass falls below tail_mass are never
  // reached: the loop below stops there. Entering no voxel past that cell saves the traversal
  // and the interval lookups of a whole chunk behind every surface; the voxel holding the cell
  // is still crossed whole.
  if (std::isnan(info_end_m)) info_end_m = InformationEnd(beam, t_ref - shift);
  const double t_last_entry = std::min(t_end_, info_end_m + shift + cell_m_);
  t_first = std::max(t_first, t_ref);
  if (t_first >= t_last_entry) return t_last_entry;
  VoxelTraversal walk(origin_, dir, t_first, options_.resolution_m);
  // A ray that starts outside the map's key range writes nothing (it never wraps around).
  if (!walk.InsideKeyRange()) return t_first;
  // Where the ray enters the voxel holding p(t_first), not before t_ref.
  const double t_entry = std::max(t_ref, walk.EntryRange());
  double t_in = std::min(t_entry, t_first);
  // The mass the ray has left behind it since t_ref, as a trace from t_ref would have counted it:
  // the first chunk's look-up reads it too ([t_ref, t_in) ahead of its crossings), unless the
  // beam's table serves the chunk and not that stretch.
  double remaining_mass = 1.0;
  bool lead = t_in > t_ref;
  if (lead && table_.valid && table_.beam == beam) {
    boundaries_.assign({t_ref - shift, t_in - shift});
    Occupancies(beam, boundaries_, &occupancy_);
    remaining_mass = 1.0 - occupancy_[0];
    if (remaining_mass < options_.tail_mass) return t_in;
    lead = false;
  }
  const double t_in_first = t_in;
  // The crossing holding the most of the ray's first-hit mass among those with occupied
  // evidence: the only one that keeps it (KeepOccupiedAtMode, at the end).
  const std::size_t first_out = out->size();
  std::size_t mode = out->size();
  double mode_mass = 0.0;
  bool done = false;
  bool left_map = false;  // the ray left the key range: it ends at the map's edge
  while (!done) {
    boundaries_.clear();
    keys_.clear();
    if (lead) boundaries_.push_back(t_ref);
    boundaries_.push_back(t_in);
    while (keys_.size() < kChunkSegments && t_in < t_last_entry && !left_map) {
      const int axis = walk.NextAxis();
      const double t_out = std::min(walk.ExitRange(axis), t_end_);
      keys_.push_back(walk.Key());
      boundaries_.push_back(t_out);
      t_in = t_out;
      left_map = !walk.Step(axis);
    }
    if (keys_.empty()) break;
    if (shift != 0.0) {
      for (double& b : boundaries_) b -= shift;
    }
    Occupancies(beam, boundaries_, &occupancy_);
    const double* bounds = boundaries_.data();
    const double* occupancy = occupancy_.data();
    if (lead) {
      lead = false;
      remaining_mass = 1.0 - occupancy_[0];
      if (remaining_mass < options_.tail_mass) return t_in_first;
      ++bounds;
      ++occupancy;
    }
    long c1 = NearestCell(bounds[0] / cell_m_);
    for (std::size_t j = 0; j < keys_.size(); ++j) {
      const long c0 = c1;
      c1 = NearestCell(bounds[j + 1] / cell_m_);
      if (c1 <= c0) continue;  // shorter than a beam cell: no evidence of its own
      const double p = occupancy[j];
      const Prior& prior = PriorOfCells(c1 - c0);
      // SegmentEvidence's dead band (prior < hazard <= 1/2: none), told without its logarithm;
      // likewise occupied evidence in a crossing that cannot become the ray's mode (it holds no
      // more of the mass than the mode so far), which KeepOccupiedAtMode would set to 0.
      const bool above_prior = p > prior.probability;
      double evidence = above_prior && (p <= 0.5 || !(remaining_mass * p > mode_mass))
                            ? 0.0
                            : SegmentEvidence(p, prior.log_odds, remaining_mass);
      evidence = std::clamp(evidence, -options_.max_abs_log_odds, options_.max_abs_log_odds);
      const double length_m = bounds[j + 1] - bounds[j];
      if (evidence > 0.0 && remaining_mass * p > mode_mass) {
        mode_mass = remaining_mass * p;
        mode = out->size();
      }
      out->push_back({keys_[j], static_cast<float>(evidence),
                      static_cast<float>(length_m) * weight_scale, bounds[j + 1] + shift});
      remaining_mass *= (1.0 - p);
      if (remaining_mass < options_.tail_mass) {
        done = true;
        t_in = bounds[j + 1] + shift;
        break;
      }
    }
    if (t_in >= t_last_entry || left_map) done = true;
  }
  KeepOccupiedAtMode(first_out, mode, out);
  return t_in;
}

void BeamTracer::Occupancies(std::size_t beam, const std::vector<double>& boundaries_m,
                             std::vector<double>* out) {
  // cells_[0] = 0 (S there is the beam's whole mass), then each boundary's cell as
  // IntervalOccupancy rounds it: its tails in one walk of the beam, or from the beam's table.
  const std::size_t n = boundaries_m.size();
  cells_.resize(n + 1);
  tails_.resize(n + 1);
  cells_[0] = 0;
  std::uint32_t previous = 0;
  for (std::size_t j = 0; j < n; ++j) {
    cells_[j + 1] = previous =
        std::max(previous, CellOfRange(boundaries_m[j], cell_m_, cells_per_beam_));
  }
  const std::uint32_t* cells = cells_.data() + 1;
  if (table_.Covers(beam, cells[0], cells[n - 1])) {
    tails_[0] = table_.total;
    for (std::size_t j = 0; j < n; ++j) tails_[j + 1] = table_.S(cells[j]);
  } else {
    grid_.TailMasses(beam, cells_.data(), n + 1, tails_.data());
  }
  out->resize(n - 1);
  const double* tail = tails_.data() + 1;
  for (std::size_t j = 0; j + 1 < n; ++j) {
    (*out)[j] =
        grid_.IntervalOccupancyOfCells(tail[j], tail[j + 1], tails_[0], cells[j + 1] - cells[j]);
  }
}

double BeamTracer::InformationEnd(std::size_t beam, double from_m) {
  const std::uint32_t from = CellOfRange(from_m, cell_m_, cells_per_beam_);
  if (table_.Covers(beam, from, from)) {
    // BeamGrid::InformationEndM: the smallest cell after `from` whose S is below the fraction.
    // S does not rise with c: bisect.
    const double threshold = options_.tail_mass * table_.S(from);
    const auto begin = table_.tails.begin() + (from + 1 - table_.first);
    const auto at = std::partition_point(begin, table_.tails.end(),
                                         [threshold](double s) { return s >= threshold; });
    if (at != table_.tails.end()) {
      return static_cast<double>(table_.first + (at - table_.tails.begin())) * cell_m_;
    }
  }
  return grid_.InformationEndM(beam, from_m, options_.tail_mass);
}

double BeamTracer::VoxelEntry(const Eigen::Vector3d& dir, double r) const {
  if (!(r > t_start_)) return t_start_;
  // VoxelTraversal's index and faces, though not its arithmetic for the far face (lo + res, not
  // (index + 1) * res): the centre ray's segments kept before the sub-rays start are those that
  // end at or before this range, which they often do exactly, so a last-bit change here changes
  // which segments a render keeps.
  const Eigen::Vector3d p = origin_ + dir * r;
  double t = t_start_;
  for (int a = 0; a < 3; ++a) {
    if (dir[a] == 0.0) continue;
    const double lo = std::floor(p[a] * inv_res_) * options_.resolution_m;
    const double face = dir[a] > 0.0 ? lo : lo + options_.resolution_m;
    t = std::max(t, r + (face - p[a]) / dir[a]);
  }
  return std::min(t, r);
}

double BeamTracer::SurfaceStep(std::size_t beam, long neighbour, long opposite,
                               double spacing_rad) const {
  const double m = profiles_[beam].median_m;
  const double n = profiles_[static_cast<std::size_t>(neighbour)].median_m;
  if (!std::isfinite(m) || !std::isfinite(n)) return 0.0;
  // On one surface seen at incidence alpha, neighbouring beams' ranges differ by about
  // r * spacing / tan(alpha); up to the shallowest incidence, the neighbour is on it.
  const double step = n - m;
  if (std::abs(step) <= continuity_ * spacing_rad * std::min(m, n)) return step;
  // Steeper: a depth edge, unless the beam on the other side steps into this one alike. A floor
  // seen at a grazing angle (a laser's, a degree or less) is a progression of ranges whose
  // steps grow slowly from row to row (o < m < n, each step within a factor ~1.5 of the last);
  // an edge is one jump between neighbours that agree.
  if (opposite < 0) return 0.0;
  const double o = profiles_[static_cast<std::size_t>(opposite)].median_m;
  if (!std::isfinite(o)) return 0.0;
  const double before = m - o;
  if (!(before * step > 0.0) || std::abs(step - before) > kProgressionTolerance * std::abs(step)) {
    return 0.0;
  }
  return step;
}

void BeamTracer::SurfaceSteps(std::size_t beam, const BeamProfile& profile, double* left,
                              double* right, double* up, double* down) const {
  // Only the max rule: the mean and the pool weigh every segment of every sub-ray, and the
  // surface's sub-rays would dilute them.
  if (!options_.follow_surfaces || options_.combine != VoxelCombine::kMaxLogOdds ||
      !std::isfinite(profile.median_m)) {
    return;
  }
  const BeamTessellation& tess = grid_.tessellation();
  const auto cols = static_cast<long>(tess.cols());
  const auto rows = static_cast<long>(tess.rows());
  const long b = static_cast<long>(beam);
  const long col = b % cols, row = b / cols;
  const long left_beam = col > 0 ? b - 1 : -1, right_beam = col + 1 < cols ? b + 1 : -1;
  const long up_beam = row > 0 ? b - cols : -1;  // elevation +
  const long down_beam = row + 1 < rows ? b + cols : -1;
  const double h = tess.beam_width_h_rad(), v = tess.beam_width_v_rad();
  if (left_beam >= 0) *left = SurfaceStep(beam, left_beam, right_beam, h);
  if (right_beam >= 0) *right = SurfaceStep(beam, right_beam, left_beam, h);
  if (up_beam >= 0) *up = SurfaceStep(beam, up_beam, down_beam, v);
  if (down_beam >= 0) *down = SurfaceStep(beam, down_beam, up_beam, v);
}

void BeamTracer::TabulateMass(std::size_t beam, const BeamProfile& profile, double reach_m) {
  // Every ray of the beam reads the same stretch: from a voxel before where the mass starts
  // (moved by the nearest sub-ray's shift) to a voxel after where it ends (the farthest shift).
  const double margin = 2.0 * options_.resolution_m + cell_m_;
  const double end = std::isfinite(profile.info_end_m) ? profile.info_end_m : t_end_;
  const std::uint32_t lo =
      CellOfRange(profile.mass_begin_m - reach_m - margin, cell_m_, cells_per_beam_);
  const std::uint32_t hi = CellOfRange(end + reach_m + margin, cell_m_, cells_per_beam_);
  if (hi > lo && hi - lo <= kMaxTableCells) {
    grid_.TailMassSpan(beam, lo, hi, &table_.tails, &table_.total);
    table_.beam = beam;
    table_.first = lo;
    table_.last = lo + static_cast<std::uint32_t>(table_.tails.size()) - 1;
    table_.valid = true;
  }
}

BeamTrace BeamTracer::TraceBeam(std::size_t beam, bool first_mass_only, std::vector<Segment>* out) {
  const BeamTessellation& tess = grid_.tessellation();
  const BeamProfile& profile = profiles_[beam];
  const double mass_begin = profile.mass_begin_m;
  const auto first = [&](double t_from, double shift) {
    return first_mass_only ? std::max(t_from, mass_begin + shift) : t_from;
  };
  BeamTrace trace;
  const Eigen::Vector3d dir_sensor = tess.Direction(beam);
  const Eigen::Vector3d dir = R_ * dir_sensor;
  const std::size_t kept_from = out->size();
  table_.valid = false;
  double left = 0.0, right = 0.0, up = 0.0, down = 0.0;
  SurfaceSteps(beam, profile, &left, &right, &up, &down);
  // Sub-rays: k_width a side where the sector outgrows a voxel, k_surface where the surface
  // runs on into a neighbour (enough that neighbouring sub-rays' surfaces lie within a voxel).
  const auto k_width_at = [&](double t_stop) {
    return std::clamp(static_cast<int>(std::ceil(width_rad_ * t_stop / options_.resolution_m)),
                      1, std::max(1, options_.max_subrays_per_axis));
  };
  const int k_max = std::max(1, options_.max_surface_subrays_per_axis);
  const auto k_surface = [&](double minus, double plus) {
    const double span = 0.5 * (std::abs(minus) + std::abs(plus));
    return std::clamp(static_cast<int>(std::ceil(span / options_.resolution_m)), 1, k_max);
  };
  // The table pays off only where several rays read the beam: a lone centre ray reads its few
  // crossings straight from the beam (a 640 x 480 grid's beams are mostly narrower than a voxel).
  const double farthest_stop =
      std::min(t_end_, profile.info_end_m) + cell_m_ + 2.0 * options_.resolution_m;
  const bool several_rays = k_width_at(farthest_stop) > 1 || k_surface(left, right) > 1 ||
                            k_surface(down, up) > 1;
  if (first_mass_only && std::isfinite(mass_begin) && several_rays) {
    const double reach =
        0.5 * (std::max(std::abs(left), std::abs(right)) + std::max(std::abs(up), std::abs(down)));
    TabulateMass(beam, profile, reach);
  }
  const double t_stop =
      Trace(beam, dir, t_start_, first(t_start_, 0.0), 0.0, 1.0f, out, profile.info_end_m);
  trace.rays = 1;
  trace.mass_begin_m = mass_begin;
  const int k_width = k_width_at(t_stop);
  const int k_u = std::max(k_width, k_surface(left, right));
  const int k_v = std::max(k_width, k_surface(down, up));
  if (k_u == 1 && k_v == 1) return trace;
  // The nearest shift of any sub-ray: where the sub-rays' mass can start.
  double min_shift = 0.0;
  {
    double su = 0.0, sv = 0.0;
    for (int i = 0; i < k_u; ++i) su = std::min(su, ShiftAt(SubOffset(i, k_u), left, right));
    for (int j = 0; j < k_v; ++j) sv = std::min(sv, ShiftAt(SubOffset(j, k_v), down, up));
    min_shift = su + sv;
  }
  // The centre ray is kept up to the voxel boundary before the sub-rays start: r_split where the
  // sector outgrows a voxel, and before the nearest shifted mass where the surface is followed.
  double r_sub = std::numeric_limits<double>::infinity();
  if (k_width > 1) r_sub = options_.resolution_m / width_rad_;
  if (k_u > k_width || k_v > k_width) {
    r_sub = std::min(r_sub, mass_begin + min_shift - options_.resolution_m);
  }
  const double t_sub = VoxelEntry(dir, r_sub);
  std::size_t keep = kept_from;
  while (keep < out->size() && (*out)[keep].t_out_m <= t_sub) ++keep;
  out->resize(keep);
  const float weight = 1.0f / static_cast<float>(k_u * k_v);
  // Unshifted sub-rays from t_sub share their information end.
  const double unshifted_info_end = t_sub == t_start_ && !std::isnan(profile.info_end_m)
                                        ? profile.info_end_m
                                        : InformationEnd(beam, t_sub);
  for (int i = 0; i < k_u; ++i) {
    const double fu = SubOffset(i, k_u);
    for (int j = 0; j < k_v; ++j) {
      const double fv = SubOffset(j, k_v);
      const double shift = ShiftAt(fu, left, right) + ShiftAt(fv, down, up);
      const Eigen::Vector3d d = tess.SubDirection(beam, fu, fv);
      Trace(beam, R_ * d, t_sub, first(t_sub, shift), shift, weight, out,
            shift == 0.0 ? unshifted_info_end : std::numeric_limits<double>::quiet_NaN());
      ++trace.rays;
    }
  }
  trace.mass_begin_m = mass_begin + min_shift;
  return trace;
}

std::size_t RowWorkers(std::size_t rows, unsigned threads) {
  const std::size_t n = threads != 0 ? threads : std::max(1u, std::thread::hardware_concurrency());
  return std::clamp<std::size_t>(n, 1, std::max<std::size_t>(1, rows / kRowsPerBlock));
}

void RunWorkers(std::size_t workers, const std::function<void(std::size_t)>& work) {
  std::vector<std::exception_ptr> errors(workers);
  const auto run = [&](std::size_t t) {
    try {
      work(t);
    } catch (...) {
      errors[t] = std::current_exception();
    }
  };
  std::vector<std::thread> helpers;
  for (std::size_t t = 1; t < workers; ++t) helpers.emplace_back(run, t);
  run(0);
  for (std::thread& h : helpers) h.join();
  for (const auto& e : errors) {
    if (e) std::rethrow_exception(e);
  }
}

void ForEachRowBlock(
    std::size_t rows, std::size_t n,
    const std::function<void(std::size_t, const std::vector<std::size_t>&)>& work) {
  std::vector<std::vector<std::size_t>> rows_of(n);
  for (std::size_t r = 0; r < rows; ++r) rows_of[(r / kRowsPerBlock) % n].push_back(r);
  RunWorkers(n, [&](std::size_t t) { work(t, rows_of[t]); });
}

}  // namespace fusion::detail
