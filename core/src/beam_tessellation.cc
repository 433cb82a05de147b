#include "fusion/core/beam_tessellation.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <utility>

namespace fusion {

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

}  // namespace fusion
