// The geometry of imported clouds, for --print-sensor: pinhole intrinsics of organized clouds,
// angular extents and spacing of any cloud.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <utility>

#include "fusion/clients/sensor_block.h"

namespace fusion::clients {

namespace {

constexpr double kDegPerRad = 180.0 / 3.14159265358979323846;

bool Finite(const float p[3]) {
  return std::isfinite(p[0]) && std::isfinite(p[1]) && std::isfinite(p[2]);
}

double Median(std::vector<double> values) {
  if (values.empty()) return 0;
  const auto middle = values.begin() + static_cast<std::ptrdiff_t>(values.size() / 2);
  std::nth_element(values.begin(), middle, values.end());
  return *middle;
}

// Returns bucketed by cells of `cell_deg` over the directions' bounding box: a sorted list of
// (cell key, index), so the returns of one cell are an equal_range.
class DirectionCells {
 public:
  DirectionCells(const std::vector<std::pair<double, double>>& directions, double azimuth_min_deg,
                 double elevation_min_deg, double cell_deg)
      : azimuth_min_deg_(azimuth_min_deg),
        elevation_min_deg_(elevation_min_deg),
        cell_deg_(cell_deg) {
    entries_.reserve(directions.size());
    for (std::size_t i = 0; i < directions.size(); ++i) {
      const auto [a, e] = Cell(directions[i]);
      entries_.emplace_back(Key(a, e), i);
    }
    std::sort(entries_.begin(), entries_.end());
  }

  std::size_t OccupiedCells() const {
    std::size_t cells = 0;
    for (std::size_t i = 0; i < entries_.size(); ++i) {
      if (i == 0 || entries_[i].first != entries_[i - 1].first) ++cells;
    }
    return cells;
  }

  // Calls visit(index) for every return in the 3 x 3 cells around `direction`.
  template <typename Visit>
  void ForNeighbours(const std::pair<double, double>& direction, Visit visit) const {
    const auto [a, e] = Cell(direction);
    for (std::int64_t da = -1; da <= 1; ++da) {
      for (std::int64_t de = -1; de <= 1; ++de) {
        if (a + da < 0 || e + de < 0) continue;
        const std::pair<std::int64_t, std::size_t> first{Key(a + da, e + de), 0};
        for (auto it = std::lower_bound(entries_.begin(), entries_.end(), first);
             it != entries_.end() && it->first == first.first; ++it) {
          visit(it->second);
        }
      }
    }
  }

 private:
  std::pair<std::int64_t, std::int64_t> Cell(const std::pair<double, double>& d) const {
    return {static_cast<std::int64_t>((d.first - azimuth_min_deg_) / cell_deg_),
            static_cast<std::int64_t>((d.second - elevation_min_deg_) / cell_deg_)};
  }
  static std::int64_t Key(std::int64_t a, std::int64_t e) { return (a << 32) + e; }

  double azimuth_min_deg_, elevation_min_deg_, cell_deg_;
  std::vector<std::pair<std::int64_t, std::size_t>> entries_;
};

// Median spacing (degrees) of a sample of returns to their nearest neighbour across (mostly
// in azimuth: |d_az| >= |d_el|) and down (mostly in elevation).
std::pair<double, double> NearestNeighbourSpacing(
    const std::vector<std::pair<double, double>>& directions, const DirectionCells& cells) {
  constexpr std::size_t kSample = 2000;
  const std::size_t step = std::max<std::size_t>(1, directions.size() / kSample);
  std::vector<double> across, down;
  for (std::size_t i = 0; i < directions.size(); i += step) {
    const auto& here = directions[i];
    double best_across = HUGE_VAL, best_down = HUGE_VAL, across_deg = 0, down_deg = 0;
    cells.ForNeighbours(here, [&](std::size_t j) {
      const double da = std::abs(directions[j].first - here.first);
      const double de = std::abs(directions[j].second - here.second);
      const double distance = std::hypot(da, de);
      if (distance < 1e-6) return;  // itself, or a repeated direction
      if (da >= de && distance < best_across) best_across = distance, across_deg = da;
      if (da < de && distance < best_down) best_down = distance, down_deg = de;
    });
    if (across_deg > 0) across.push_back(across_deg);
    if (down_deg > 0) down.push_back(down_deg);
  }
  return {Median(across), Median(down)};
}

// Azimuth and elevation steps (degrees) of returns spread over a box of the given spans.
std::pair<double, double> EstimateSteps(const std::vector<std::pair<double, double>>& directions,
                                        double azimuth_min_deg, double azimuth_span_deg,
                                        double elevation_min_deg, double elevation_span_deg) {
  const double n = static_cast<double>(directions.size());
  if (std::min(azimuth_span_deg, elevation_span_deg) < 1e-3) {  // one line of returns
    const double step = std::max(azimuth_span_deg, elevation_span_deg) / (n - 1);
    return {step, step};
  }
  const double cell_deg = 4 * std::sqrt(azimuth_span_deg * elevation_span_deg / n);
  const DirectionCells cells(directions, azimuth_min_deg, elevation_min_deg, cell_deg);
  const double area_per_return_deg2 =
      static_cast<double>(cells.OccupiedCells()) * cell_deg * cell_deg / n;
  const auto [across, down] = NearestNeighbourSpacing(directions, cells);
  const double aspect = across > 0 && down > 0 ? std::clamp(across / down, 0.125, 8.0) : 1.0;
  const double step = std::sqrt(area_per_return_deg2);
  return {step * std::sqrt(aspect), step / std::sqrt(aspect)};
}

// [min - step, max + step] rounded out to 0.1 deg inside [-limit, limit]; the beams of about
// `step` that cover it.
void WidenAndDivide(double min_deg, double max_deg, double step_deg, double limit_deg,
                    double* out_min_deg, double* out_max_deg, std::uint32_t* beams) {
  *out_min_deg = std::max(-limit_deg, std::floor((min_deg - step_deg) * 10) / 10);
  *out_max_deg = std::min(limit_deg, std::ceil((max_deg + step_deg) * 10) / 10);
  const double count = std::round((*out_max_deg - *out_min_deg) / step_deg);
  *beams = static_cast<std::uint32_t>(std::clamp(count, 1.0, 100000.0));
}

}  // namespace

void PinholeEstimator::Line::Add(double a_value, double p_value) {
  n += 1;
  a += a_value;
  aa += a_value * a_value;
  p += p_value;
  ap += a_value * p_value;
  pp += p_value * p_value;
}

bool PinholeEstimator::Add(const fusion::v1::RecordedCloud& cloud) {
  if (cloud.height() <= 1) return false;
  if (width_px_ == 0) width_px_ = cloud.width(), height_px_ = cloud.height();
  if (cloud.width() != width_px_ || cloud.height() != height_px_) return false;
  const std::size_t n = cloud.xyz_f32le().size() / 12;
  for (std::size_t i = 0; i < n && i < std::size_t{width_px_} * height_px_; ++i) {
    float p[3];
    GetPoint(cloud, i, p);
    if (!Finite(p) || !(p[2] > 0)) continue;
    u_.Add(double{p[0]} / p[2], static_cast<double>(i % width_px_));
    v_.Add(double{p[1]} / p[2], static_cast<double>(i / width_px_));
  }
  return true;
}

Status PinholeEstimator::Fit(PinholeFit* fit) const {
  // Solves p = f a + c; *sse: the sum of squared residuals.
  const auto solve = [](const Line& l, double* f, double* c, double* sse) {
    const double det = l.n * l.aa - l.a * l.a;
    if (l.n < 3 || !(det > 1e-12 * l.n * l.n)) return false;
    *f = (l.n * l.ap - l.a * l.p) / det;
    *c = (l.p - *f * l.a) / l.n;
    *sse = std::max(0.0, l.pp - 2 * *f * l.ap - 2 * *c * l.p + *f * *f * l.aa + 2 * *f * *c * l.a +
                             l.n * *c * *c);
    return *f > 0;
  };
  double sse_u = 0, sse_v = 0;
  if (!solve(u_, &fit->fx_px, &fit->cx_px, &sse_u) ||
      !solve(v_, &fit->fy_px, &fit->cy_px, &sse_v)) {
    return Status::Error("too few returns in front of the camera (z > 0) to fit a pinhole camera");
  }
  fit->width_px = width_px_;
  fit->height_px = height_px_;
  fit->points = static_cast<std::uint64_t>(u_.n);
  fit->rms_px = std::sqrt((sse_u + sse_v) / (2 * u_.n));
  return Status::Ok();
}

void AngularEstimator::Add(const fusion::v1::RecordedCloud& cloud) {
  std::vector<Direction> directions;
  const std::size_t n = cloud.xyz_f32le().size() / 12;
  directions.reserve(n);
  for (std::size_t i = 0; i < n; ++i) {
    float p[3];
    GetPoint(cloud, i, p);
    if (!Finite(p) || (p[0] == 0 && p[1] == 0 && p[2] == 0)) continue;
    const double azimuth_deg = std::atan2(double{p[0]}, double{p[2]}) * kDegPerRad;
    const double elevation_deg =
        std::atan2(-double{p[1]}, std::hypot(double{p[0]}, double{p[2]})) * kDegPerRad;
    azimuth_min_deg_ = std::min(azimuth_min_deg_, azimuth_deg);
    azimuth_max_deg_ = std::max(azimuth_max_deg_, azimuth_deg);
    elevation_min_deg_ = std::min(elevation_min_deg_, elevation_deg);
    elevation_max_deg_ = std::max(elevation_max_deg_, elevation_deg);
    directions.push_back({static_cast<float>(azimuth_deg), static_cast<float>(elevation_deg)});
  }
  if (directions.size() > densest_.size()) densest_ = std::move(directions);
}

Status AngularEstimator::Fit(AngularGrid* grid) const {
  if (densest_.size() < 2) {
    return Status::Error("too few returns to estimate the angular spacing (need 2 in one cloud)");
  }
  std::vector<std::pair<double, double>> directions;
  directions.reserve(densest_.size());
  double a_min = 180, a_max = -180, e_min = 90, e_max = -90;
  for (const Direction& d : densest_) {
    directions.emplace_back(d.azimuth_deg, d.elevation_deg);
    a_min = std::min(a_min, double{d.azimuth_deg});
    a_max = std::max(a_max, double{d.azimuth_deg});
    e_min = std::min(e_min, double{d.elevation_deg});
    e_max = std::max(e_max, double{d.elevation_deg});
  }
  if (a_max - a_min < 1e-3 && e_max - e_min < 1e-3) {
    return Status::Error("every return lies in one direction: no field of view to estimate");
  }
  auto [a_step, e_step] = EstimateSteps(directions, a_min, a_max - a_min, e_min, e_max - e_min);
  const double returns = static_cast<double>(directions.size());
  // Returns bunched up in a wide field of view: coarser beams, at most 4 per return (a few
  // tries, as rounding the extents moves the count).
  for (int pass = 0;; ++pass) {
    WidenAndDivide(azimuth_min_deg_, azimuth_max_deg_, a_step, 180, &grid->azimuth_min_deg,
                   &grid->azimuth_max_deg, &grid->cols);
    WidenAndDivide(elevation_min_deg_, elevation_max_deg_, e_step, 89.9, &grid->elevation_min_deg,
                   &grid->elevation_max_deg, &grid->rows);
    const double beams = static_cast<double>(grid->cols) * grid->rows;
    if (beams <= 4 * returns || pass == 5) break;
    const double coarser = 1.02 * std::sqrt(beams / (4 * returns));
    a_step *= coarser;
    e_step *= coarser;
  }
  grid->azimuth_step_deg = a_step;
  grid->elevation_step_deg = e_step;
  grid->returns_per_scan = densest_.size();
  return Status::Ok();
}

}  // namespace fusion::clients
