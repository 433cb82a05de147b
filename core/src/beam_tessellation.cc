#include "fusion/core/beam_tessellation.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <utility>

namespace fusion {
namespace {

constexpr double kPi = 3.14159265358979323846;

}  // namespace

BeamTessellation::BeamTessellation(const SensorSpec& spec)
    : cols_(spec.cols),
      rows_(spec.rows),
      fov_h_rad_(spec.fov_h_rad),
      fov_v_rad_(spec.fov_v_rad),
      azimuth_min_rad_(spec.azimuth_centre_rad - 0.5 * spec.fov_h_rad),
      elevation_max_rad_(spec.elevation_centre_rad + 0.5 * spec.fov_v_rad),
      pinhole_(spec.pinhole) {
  if (cols_ < 1 || rows_ < 1 || !(fov_h_rad_ > 0.0) || !(fov_v_rad_ > 0.0) ||
      !std::isfinite(fov_h_rad_) || !std::isfinite(fov_v_rad_) ||
      !std::isfinite(azimuth_min_rad_) || !std::isfinite(elevation_max_rad_)) {
    throw std::invalid_argument("tessellation needs cols, rows >= 1 and a positive FOV");
  }
  std::vector<double> cols, rows;
  if (pinhole_) {
    const PinholeIntrinsics& k = *pinhole_;
    if (!(k.fx_px > 0.0) || !(k.fy_px > 0.0) || k.stride < 1 ||
        cols_ != (k.width_px + k.stride - 1) / k.stride ||
        rows_ != (k.height_px + k.stride - 1) / k.stride) {
      throw std::invalid_argument("pinhole tessellation needs fx, fy > 0 and its image's beams");
    }
    // Column edges on the image plane, left to right; row edges bottom (the last row) to top.
    for (int c = 0; c <= cols_; ++c) {
      const double u = std::min(c * k.stride, k.width_px) - 0.5;
      cols.push_back((u - k.cx_px) / k.fx_px);
    }
    for (int r = rows_; r >= 0; --r) {
      const double v = std::min(r * k.stride, k.height_px) - 0.5;
      rows.push_back(-(v - k.cy_px) / k.fy_px);
    }
  } else if (azimuth_min_rad_ > -0.5 * kPi && azimuth_min_rad_ + fov_h_rad_ < 0.5 * kPi &&
             elevation_max_rad_ < 0.5 * kPi && elevation_max_rad_ - fov_v_rad_ > -0.5 * kPi) {
    for (int k = 0; k <= cols_; ++k) {
      cols.push_back(std::tan(azimuth_min_rad_ + k * beam_width_h_rad()));
    }
    for (int k = rows_; k >= 0; --k) {
      rows.push_back(std::tan(elevation_max_rad_ - k * beam_width_v_rad()));
    }
  }
  if (!pinhole_) {
    for (int c = 0; c < cols_; ++c) {
      const double azimuth = azimuth_min_rad_ + (c + 0.5) * beam_width_h_rad();
      col_sin_cos_.push_back({std::sin(azimuth), std::cos(azimuth)});
    }
    for (int r = 0; r < rows_; ++r) {
      const double elevation = elevation_max_rad_ - (r + 0.5) * beam_width_v_rad();
      row_sin_cos_.push_back({std::sin(elevation), std::cos(elevation)});
    }
  }
  if (!cols.empty()) {
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

std::size_t BeamTessellation::beam_count() const {
  return static_cast<std::size_t>(cols_) * static_cast<std::size_t>(rows_);
}
int BeamTessellation::cols() const { return cols_; }
int BeamTessellation::rows() const { return rows_; }

double BeamTessellation::beam_width_h_rad() const {
  return pinhole_ ? pinhole_->stride / pinhole_->fx_px : fov_h_rad_ / cols_;
}
double BeamTessellation::beam_width_v_rad() const {
  return pinhole_ ? pinhole_->stride / pinhole_->fy_px : fov_v_rad_ / rows_;
}

std::optional<std::size_t> BeamTessellation::BeamOf(const Eigen::Vector3d& p_sensor) const {
  if (tan_col_edges_.empty()) return BeamOfByAngles(p_sensor);
  const double x = p_sensor.x();
  const double y = p_sensor.y();
  const double z = p_sensor.z();
  if (!std::isfinite(x) || !std::isfinite(y) || !std::isfinite(z)) return std::nullopt;
  // Every azimuth is within +-90 degrees: a direction with z <= 0 is outside (and so is the
  // zero vector). Within, the tangents grow with the angles.
  if (!(z > 0.0)) return std::nullopt;
  const double tan_azimuth = x / z;
  const double tan_elevation = -y / (pinhole_ ? z : std::sqrt(x * x + z * z));
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

std::optional<std::size_t> BeamTessellation::BeamOfByAngles(const Eigen::Vector3d& p_sensor) const {
  const double x = p_sensor.x();
  const double y = p_sensor.y();
  const double z = p_sensor.z();
  if (!std::isfinite(x) || !std::isfinite(y) || !std::isfinite(z)) return std::nullopt;
  if (x == 0.0 && y == 0.0 && z == 0.0) return std::nullopt;
  double u = 0.0, v = 0.0;  // 0 at the left / top edge, 1 at the right / bottom one
  if (pinhole_) {
    const PinholeIntrinsics& k = *pinhole_;
    if (!(z > 0.0)) return std::nullopt;
    u = (k.fx_px * x / z + k.cx_px + 0.5) / k.width_px;
    v = (k.fy_px * y / z + k.cy_px + 0.5) / k.height_px;
  } else {
    const double azimuth = std::atan2(x, z);
    const double elevation = std::atan2(-y, std::hypot(x, z));
    u = (azimuth - azimuth_min_rad_) / fov_h_rad_;
    v = (elevation_max_rad_ - elevation) / fov_v_rad_;
  }
  if (!(u >= 0.0 && u <= 1.0 && v >= 0.0 && v <= 1.0)) return std::nullopt;
  int col = 0, row = 0;
  if (pinhole_) {
    col = static_cast<int>(u * pinhole_->width_px) / pinhole_->stride;
    row = static_cast<int>(v * pinhole_->height_px) / pinhole_->stride;
  } else {
    col = static_cast<int>(u * cols_);
    row = static_cast<int>(v * rows_);
  }
  col = std::min(cols_ - 1, col);
  row = std::min(rows_ - 1, row);
  return static_cast<std::size_t>(row) * static_cast<std::size_t>(cols_) +
         static_cast<std::size_t>(col);
}

BeamTessellation::PixelSpan BeamTessellation::SpanOf(int index, int pixels) const {
  const int s = pinhole_->stride;
  const int first = index * s;
  return {first - 0.5, static_cast<double>(std::min(first + s, pixels) - first)};
}

double BeamTessellation::ColumnCentreTangent(int col) const {
  if (!pinhole_) return std::tan(azimuth_min_rad_ + (col + 0.5) * beam_width_h_rad());
  const PixelSpan span = SpanOf(col, pinhole_->width_px);
  return (span.lo + 0.5 * span.width - pinhole_->cx_px) / pinhole_->fx_px;
}

double BeamTessellation::RowCentreTangent(int row) const {
  if (!pinhole_) return std::tan(elevation_max_rad_ - (row + 0.5) * beam_width_v_rad());
  const PixelSpan span = SpanOf(row, pinhole_->height_px);
  return -(span.lo + 0.5 * span.width - pinhole_->cy_px) / pinhole_->fy_px;
}

BeamTessellation::TangentBounds BeamTessellation::InsetTangents(double beams) const {
  return InsetTangents(beams, 0, cols_ - 1, 0, rows_ - 1);
}

BeamTessellation::TangentBounds BeamTessellation::InsetTangents(double beams, int col_lo,
                                                                int col_hi, int row_lo,
                                                                int row_hi) const {
  // Row edges are kept bottom to top: row r's top edge is edge rows - r.
  const double left = tan_col_edges_.at(col_lo), right = tan_col_edges_.at(col_hi + 1);
  const double bottom = tan_row_edges_.at(rows_ - row_hi - 1);
  const double top = tan_row_edges_.at(rows_ - row_lo);
  if (pinhole_) {
    // On the image plane a beam is stride pixels wide (the last one maybe fewer: at 0.5 the
    // bounds are still its centre line, as the render's outermost rays run there).
    const PinholeIntrinsics& k = *pinhole_;
    const double w_left = SpanOf(col_lo, k.width_px).width;
    const double w_right = SpanOf(col_hi, k.width_px).width;
    const double h_top = SpanOf(row_lo, k.height_px).width;
    const double h_bottom = SpanOf(row_hi, k.height_px).width;
    return {left + beams * w_left / k.fx_px, right - beams * w_right / k.fx_px,
            bottom + beams * h_bottom / k.fy_px, top - beams * h_top / k.fy_px};
  }
  const double w = beams * beam_width_h_rad();
  const double h = beams * beam_width_v_rad();
  return {std::tan(std::atan(left) + w), std::tan(std::atan(right) - w),
          std::tan(std::atan(bottom) + h), std::tan(std::atan(top) - h)};
}

Eigen::Vector3d BeamTessellation::Direction(std::size_t beam) const {
  if (pinhole_ || beam >= beam_count()) return SubDirection(beam, 0.0, 0.0);
  const auto& az = col_sin_cos_[beam % static_cast<std::size_t>(cols_)];
  const auto& el = row_sin_cos_[beam / static_cast<std::size_t>(cols_)];
  return {el[1] * az[0], -el[0], el[1] * az[1]};
}

Eigen::Vector3d BeamTessellation::SubDirection(std::size_t beam, double right, double up) const {
  if (beam >= beam_count()) throw std::out_of_range("beam index out of range");
  const int col = static_cast<int>(beam % static_cast<std::size_t>(cols_));
  const int row = static_cast<int>(beam / static_cast<std::size_t>(cols_));
  if (pinhole_) {
    const PinholeIntrinsics& k = *pinhole_;
    const PixelSpan su = SpanOf(col, k.width_px);
    const PixelSpan sv = SpanOf(row, k.height_px);
    const double u = su.lo + (0.5 + right) * su.width;
    const double v = sv.lo + (0.5 - up) * sv.width;
    return Eigen::Vector3d((u - k.cx_px) / k.fx_px, (v - k.cy_px) / k.fy_px, 1.0).normalized();
  }
  const double azimuth = azimuth_min_rad_ + (col + 0.5 + right) * beam_width_h_rad();
  const double elevation = elevation_max_rad_ - (row + 0.5 - up) * beam_width_v_rad();
  return {std::cos(elevation) * std::sin(azimuth), -std::sin(elevation),
          std::cos(elevation) * std::cos(azimuth)};
}

}  // namespace fusion
