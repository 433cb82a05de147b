// Beam tessellation of a sensor's field of view and the per-sensor beam grid.
#include "fusion/core/beam_grid.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>
#include <utility>

#include "fusion/core/beam.h"
#include "fusion/core/forward_model.h"

namespace fusion {

// ---------------------------------------------------------------------------------------------
// BeamTessellation

BeamTessellation::BeamTessellation(const SensorSpec& spec)
    : cols_(spec.cols), rows_(spec.rows), fov_h_rad_(spec.fov_h_rad), fov_v_rad_(spec.fov_v_rad) {
  if (cols_ < 1 || rows_ < 1 || !(fov_h_rad_ > 0.0) || !(fov_v_rad_ > 0.0) ||
      !std::isfinite(fov_h_rad_) || !std::isfinite(fov_v_rad_)) {
    throw std::invalid_argument("tessellation needs cols, rows >= 1 and a positive FOV");
  }
  constexpr double kPi = 3.14159265358979323846;
  if (fov_h_rad_ < kPi && fov_v_rad_ < kPi) {
    std::vector<double> cols, rows;
    for (int k = 0; k <= cols_; ++k) {
      cols.push_back(std::tan(-0.5 * fov_h_rad_ + k * beam_width_h_rad()));
    }
    for (int k = rows_; k >= 0; --k) {
      rows.push_back(std::tan(0.5 * fov_v_rad_ - k * beam_width_v_rad()));
    }
    tan_col_edges_ = Edges(std::move(cols));
    tan_row_edges_ = Edges(std::move(rows));
  }
}

BeamTessellation::Edges::Edges(std::vector<double> edges) : edges_(std::move(edges)) {
  // Buckets of at most half the narrowest gap between edges: a bucket holds at most one edge.
  const std::size_t n = edges_.size() - 1;
  double narrowest = std::numeric_limits<double>::infinity();
  for (std::size_t k = 0; k < n; ++k) narrowest = std::min(narrowest, edges_[k + 1] - edges_[k]);
  const double span = edges_.back() - edges_.front();
  const auto buckets = static_cast<std::size_t>(
      std::min(std::ceil(2.0 * span / narrowest), 1e6)) + 1;
  inverse_bucket_ = static_cast<double>(buckets) / span;
  start_.resize(buckets + 1);
  for (std::size_t b = 0; b <= buckets; ++b) {
    // Edges below the bucket's lower end, taken a little low so that rounding in Start never
    // counts an edge above the value.
    const double lower = edges_.front() + (static_cast<double>(b) - 0.01) / inverse_bucket_;
    start_[b] = static_cast<int>(std::lower_bound(edges_.begin() + 1, edges_.end() - 1, lower) -
                                 (edges_.begin() + 1));
  }
}

int BeamTessellation::Edges::Start(double v) const {
  const double bucket = (v - edges_.front()) * inverse_bucket_;
  const auto b = static_cast<std::size_t>(
      std::clamp(bucket, 0.0, static_cast<double>(start_.size() - 1)));
  return start_[b];
}

int BeamTessellation::Edges::InnerAtOrBelow(double v) const {
  const int inner = static_cast<int>(edges_.size()) - 2;
  int count = Start(v);
  while (count < inner && edges_[static_cast<std::size_t>(count) + 1] <= v) ++count;
  return count;
}

int BeamTessellation::Edges::InnerBelow(double v) const {
  const int inner = static_cast<int>(edges_.size()) - 2;
  int count = Start(v);
  while (count < inner && edges_[static_cast<std::size_t>(count) + 1] < v) ++count;
  return count;
}

std::size_t BeamTessellation::beam_count() const {
  return static_cast<std::size_t>(cols_) * static_cast<std::size_t>(rows_);
}
int BeamTessellation::cols() const { return cols_; }
int BeamTessellation::rows() const { return rows_; }
double BeamTessellation::beam_width_h_rad() const { return fov_h_rad_ / cols_; }
double BeamTessellation::beam_width_v_rad() const { return fov_v_rad_ / rows_; }

std::optional<std::size_t> BeamTessellation::BeamOf(const Eigen::Vector3d& p_sensor) const {
  if (tan_col_edges_.empty()) return BeamOfByAngles(p_sensor);
  const double x = p_sensor.x();
  const double y = p_sensor.y();
  const double z = p_sensor.z();
  if (!std::isfinite(x) || !std::isfinite(y) || !std::isfinite(z)) return std::nullopt;
  // Both half-FOVs are below 90 degrees: a direction with z <= 0 is outside (and so is the
  // zero vector). Within, the tangents grow with the angles.
  if (!(z > 0.0)) return std::nullopt;
  const double tan_azimuth = x / z;
  const double tan_elevation = -y / std::sqrt(x * x + z * z);
  if (!tan_col_edges_.Contains(tan_azimuth) || !tan_row_edges_.Contains(tan_elevation)) {
    return std::nullopt;
  }
  // Column: the inner edges at or left of the direction. Row (0 at the top): the inner edges
  // at or above it.
  const int col = tan_col_edges_.InnerAtOrBelow(tan_azimuth);
  const int row = (rows_ - 1) - tan_row_edges_.InnerBelow(tan_elevation);
  return static_cast<std::size_t>(row) * static_cast<std::size_t>(cols_) +
         static_cast<std::size_t>(col);
}

int BeamTessellation::ColumnOfTangent(double tan_azimuth) const {
  const double v = std::clamp(tan_azimuth, tan_col_edges_.lo(), tan_col_edges_.hi());
  return tan_col_edges_.InnerAtOrBelow(v);
}

int BeamTessellation::RowOfTangent(double tan_elevation) const {
  const double v = std::clamp(tan_elevation, tan_row_edges_.lo(), tan_row_edges_.hi());
  return (rows_ - 1) - tan_row_edges_.InnerBelow(v);
}

std::optional<std::size_t> BeamTessellation::BeamOfByAngles(const Eigen::Vector3d& p_sensor) const {
  const double x = p_sensor.x();
  const double y = p_sensor.y();
  const double z = p_sensor.z();
  if (!std::isfinite(x) || !std::isfinite(y) || !std::isfinite(z)) return std::nullopt;
  if (x == 0.0 && y == 0.0 && z == 0.0) return std::nullopt;
  const double azimuth = std::atan2(x, z);
  const double elevation = std::atan2(-y, std::hypot(x, z));
  const double u = (azimuth + 0.5 * fov_h_rad_) / fov_h_rad_;    // 0 at the left edge
  const double v = (0.5 * fov_v_rad_ - elevation) / fov_v_rad_;  // 0 at the top edge
  if (!(u >= 0.0 && u <= 1.0 && v >= 0.0 && v <= 1.0)) return std::nullopt;
  const int col = std::min(cols_ - 1, static_cast<int>(u * cols_));
  const int row = std::min(rows_ - 1, static_cast<int>(v * rows_));
  return static_cast<std::size_t>(row) * static_cast<std::size_t>(cols_) +
         static_cast<std::size_t>(col);
}

Eigen::Vector3d BeamTessellation::Direction(std::size_t beam) const {
  if (beam >= beam_count()) throw std::out_of_range("beam index out of range");
  const int col = static_cast<int>(beam % static_cast<std::size_t>(cols_));
  const int row = static_cast<int>(beam / static_cast<std::size_t>(cols_));
  const double azimuth = -0.5 * fov_h_rad_ + (col + 0.5) * beam_width_h_rad();
  const double elevation = 0.5 * fov_v_rad_ - (row + 0.5) * beam_width_v_rad();
  return {std::cos(elevation) * std::sin(azimuth), -std::sin(elevation),
          std::cos(elevation) * std::cos(azimuth)};
}

// ---------------------------------------------------------------------------------------------
// BeamGrid

struct BeamGrid::Impl {
  Impl(const SensorSpec& s, const BeamGridOptions& o)
      : Impl(s, o, std::make_shared<const BeamContext>(s, o)) {}
  Impl(const SensorSpec& s, const BeamGridOptions& o, std::shared_ptr<const BeamContext> c)
      : spec(s),
        options(o),
        tessellation(s),
        context(std::move(c)),
        store(MakeBeamStore(o.representation, context, tessellation.beam_count())) {}

  SensorSpec spec;
  BeamGridOptions options;
  BeamTessellation tessellation;
  std::shared_ptr<const BeamContext> context;
  std::unique_ptr<BeamStore> store;
  std::vector<BeamStore::BeamOutcome> scratch;  // reused by Integrate / UpdateEachBeam

  void CheckBeam(std::size_t beam) const {
    if (beam >= store->beam_count()) throw std::out_of_range("beam index out of range");
  }
};

BeamGrid::BeamGrid(const SensorSpec& spec, const BeamGridOptions& options)
    : impl_(std::make_unique<Impl>(spec, options)) {}
BeamGrid::BeamGrid(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}

std::unique_ptr<BeamGrid> BeamGrid::EmptyCopy() const {
  return std::unique_ptr<BeamGrid>(
      new BeamGrid(std::make_unique<Impl>(impl_->spec, impl_->options, impl_->context)));
}

BeamGrid::~BeamGrid() = default;
BeamGrid::BeamGrid(BeamGrid&&) noexcept = default;
BeamGrid& BeamGrid::operator=(BeamGrid&&) noexcept = default;

const SensorSpec& BeamGrid::spec() const { return impl_->spec; }
const BeamGridOptions& BeamGrid::options() const { return impl_->options; }
const BeamTessellation& BeamGrid::tessellation() const { return impl_->tessellation; }
std::size_t BeamGrid::cells_per_beam() const { return impl_->context->cell_count(); }
std::size_t BeamGrid::beam_count() const { return impl_->store->beam_count(); }
double BeamGrid::prior_cell_occupancy() const { return impl_->context->prior(); }
std::size_t BeamGrid::first_visible_cell() const {
  return impl_->context->disc().first_visible_cell;
}
double BeamGrid::r_limit_m() const { return impl_->context->disc().r_limit_m; }

IntegrationStats BeamGrid::Integrate(const float* points_xyz, std::size_t point_count,
                                     const std::vector<std::uint8_t>& beyond_range) {
  IntegrationStats stats;
  if (point_count == 0) return stats;
  if (points_xyz == nullptr) throw std::invalid_argument("points_xyz is null");
  if (!beyond_range.empty() && beyond_range.size() != point_count) {
    throw std::invalid_argument("beyond_range has " + std::to_string(beyond_range.size()) +
                                " flags for " + std::to_string(point_count) + " points");
  }
  const BeamDiscretisation& disc = impl_->context->disc();
  std::vector<BeamStore::BeamOutcome>& todo = impl_->scratch;
  todo.clear();
  for (std::size_t k = 0; k < point_count; ++k) {
    const float* p = points_xyz + 3 * k;
    const bool nan_x = std::isnan(p[0]);
    const bool nan_y = std::isnan(p[1]);
    const bool nan_z = std::isnan(p[2]);
    if (nan_x && nan_y && nan_z) {
      ++stats.missing;
      continue;
    }
    if (!std::isfinite(p[0]) || !std::isfinite(p[1]) || !std::isfinite(p[2])) {
      ++stats.rejected_nonfinite;
      continue;
    }
    const Eigen::Vector3d point(p[0], p[1], p[2]);
    if (point.x() == 0.0 && point.y() == 0.0 && point.z() == 0.0) {
      ++stats.missing;
      continue;
    }
    const std::optional<std::size_t> beam = impl_->tessellation.BeamOf(point);
    if (!beam) {
      ++stats.rejected_outside_fov;
      continue;
    }
    Reading reading;
    if (!beyond_range.empty() && beyond_range[k] != 0) {
      reading.kind = Reading::Kind::kBeyondRange;
    } else {
      reading.kind = Reading::Kind::kRange;
      reading.range_m = point.norm();
    }
    const std::optional<std::size_t> outcome = disc.OutcomeOf(reading);
    if (!outcome) {  // unreachable for finite non-zero points; counted, never applied
      ++stats.rejected_nonfinite;
      continue;
    }
    todo.push_back({static_cast<std::uint32_t>(*beam), static_cast<std::uint32_t>(*outcome)});
    if (*outcome == disc.beyond_outcome()) {
      ++stats.beyond_range;
    } else {
      ++stats.updated;
    }
  }
  impl_->store->UpdateMany(todo.data(), todo.size());
  return stats;
}

IntegrationStats BeamGrid::UpdateEachBeam(const std::vector<Reading>& readings) {
  if (readings.size() != beam_count()) {
    throw std::invalid_argument("UpdateEachBeam needs one reading per beam (" +
                                std::to_string(beam_count()) + "), got " +
                                std::to_string(readings.size()));
  }
  IntegrationStats stats;
  const BeamDiscretisation& disc = impl_->context->disc();
  std::vector<BeamStore::BeamOutcome>& todo = impl_->scratch;
  todo.clear();
  for (std::size_t b = 0; b < readings.size(); ++b) {
    const std::optional<std::size_t> outcome = disc.OutcomeOf(readings[b]);
    if (!outcome) {
      ++stats.missing;
      continue;
    }
    todo.push_back({static_cast<std::uint32_t>(b), static_cast<std::uint32_t>(*outcome)});
    if (*outcome == disc.beyond_outcome()) {
      ++stats.beyond_range;
    } else {
      ++stats.updated;
    }
  }
  impl_->store->UpdateMany(todo.data(), todo.size());
  return stats;
}

bool BeamGrid::Update(std::size_t beam, const Reading& reading) {
  impl_->CheckBeam(beam);
  const std::optional<std::size_t> outcome = impl_->context->disc().OutcomeOf(reading);
  if (!outcome) return false;
  impl_->store->Update(beam, *outcome);
  return true;
}

std::vector<double> BeamGrid::FirstHitProbabilities(std::size_t beam) const {
  impl_->CheckBeam(beam);
  std::vector<double> w;
  impl_->store->Weights(beam, &w);
  double total = 0.0;
  for (std::size_t i = w.size(); i-- > 0;) total += w[i];
  const double eta = 1.0 / total;
  for (double& v : w) v *= eta;
  return w;
}

std::vector<double> BeamGrid::CellProbabilities(std::size_t beam) const {
  impl_->CheckBeam(beam);
  std::vector<double> w;
  impl_->store->Weights(beam, &w);
  return CellsFromFirstHit(w, impl_->context->prior());
}

void BeamGrid::IntervalOccupancy(std::size_t beam, const std::vector<double>& boundaries_m,
                                 std::vector<double>* out) const {
  impl_->CheckBeam(beam);
  out->clear();
  if (boundaries_m.size() < 2) return;
  // cells[0] = 0 (the whole beam's mass), then one cell per boundary; one TailMasses walk
  // answers both. Scratch per thread: renders call this from several threads.
  thread_local std::vector<std::uint32_t> cells;
  thread_local std::vector<double> tails;
  cells.resize(boundaries_m.size() + 1);
  cells[0] = 0;
  std::uint32_t previous = 0;
  for (std::size_t j = 0; j < boundaries_m.size(); ++j) {
    const std::uint32_t ci = std::max(previous, CellOf(boundaries_m[j]));  // ascending
    cells[j + 1] = ci;
    previous = ci;
  }
  impl_->store->TailMasses(beam, cells, &tails);
  const double* tail = tails.data() + 1;
  out->resize(boundaries_m.size() - 1);
  for (std::size_t j = 0; j + 1 < boundaries_m.size(); ++j) {
    (*out)[j] = IntervalOccupancyOfCells(tail[j], tail[j + 1], tails[0], cells[j + 2] - cells[j + 1]);
  }
}

std::uint32_t BeamGrid::CellOf(double range_m) const {
  double c = std::round(range_m / impl_->options.cell_size_m);
  if (!(c >= 0.0)) c = 0.0;  // NaN and negatives
  return static_cast<std::uint32_t>(std::min(c, static_cast<double>(cells_per_beam())));
}

double BeamGrid::IntervalOccupancyOfCells(double tail_a, double tail_b, double total,
                                          std::uint32_t cells) const {
  if (tail_a > kNoInformationTail * total) {
    // Telescoping Eq. 8: prod_{i in [a, b)} (1 - p(m_i)) = S_b / S_a.
    return std::clamp(1.0 - tail_b / tail_a, 0.0, 1.0);
  }
  return PriorOccupancy(static_cast<double>(cells) * impl_->options.cell_size_m);
}

void BeamGrid::TailMassSpan(std::size_t beam, std::uint32_t first, std::uint32_t last,
                            std::vector<double>* tails, double* total) const {
  impl_->CheckBeam(beam);
  const auto n = static_cast<std::uint32_t>(cells_per_beam());
  first = std::min(first, n);
  last = std::min(std::max(last, first), n);
  impl_->store->TailSpan(beam, first, last, tails, total);
}

double BeamGrid::InformationEndM(std::size_t beam, double from_m, double fraction) const {
  impl_->CheckBeam(beam);
  const std::size_t n = cells_per_beam();
  const double cell = impl_->options.cell_size_m;
  double from = std::round(from_m / cell);
  if (!(from >= 0.0)) from = 0.0;
  from = std::min(from, static_cast<double>(n));
  const std::uint32_t c =
      impl_->store->TailDropCell(beam, static_cast<std::uint32_t>(from), fraction);
  if (c > n) return std::numeric_limits<double>::infinity();
  return static_cast<double>(c) * cell;
}

BeamProfile BeamGrid::Profile(std::size_t beam, double from_m, double tail_fraction,
                              double free_ratio) const {
  impl_->CheckBeam(beam);
  const std::size_t n = cells_per_beam();
  const double cell = impl_->options.cell_size_m;
  double from = std::round(from_m / cell);
  if (!(from >= 0.0)) from = 0.0;
  from = std::min(from, static_cast<double>(n));
  const auto start = static_cast<std::uint32_t>(from);
  const BeamProfileCells cells = impl_->store->Profile(beam, start, tail_fraction, free_ratio);
  constexpr double kInf = std::numeric_limits<double>::infinity();
  BeamProfile out;
  out.mass_begin_m = cells.mass_begin > n ? kInf : cells.mass_begin * cell;
  out.info_end_m = cells.info_end > n ? kInf : cells.info_end * cell;
  out.median_m = cells.median > n ? kInf : cells.median * cell;
  const std::size_t end = std::min<std::size_t>(cells.mass_begin, n);
  if (end <= start) {
    out.free_log_odds = -kInf;
  } else {
    const double prior_hazard = -std::log1p(-impl_->context->prior()) * double(end - start);
    out.free_log_odds = std::log(std::max(cells.free_hazard, 1e-300) / prior_hazard);
  }
  return out;
}

double BeamGrid::PriorOccupancy(double length_m) const {
  if (!(length_m > 0.0)) return 0.0;
  return -std::expm1(std::log1p(-impl_->context->prior()) * length_m / impl_->options.cell_size_m);
}

bool BeamGrid::Touched(std::size_t beam) const {
  impl_->CheckBeam(beam);
  return impl_->store->Touched(beam);
}

void BeamGrid::Reset() { impl_->store->Reset(); }

std::size_t BeamGrid::MemoryBytes() const {
  return sizeof(*this) + sizeof(Impl) + impl_->store->MemoryBytes() + impl_->context->MemoryBytes();
}

}  // namespace fusion
