// A sensor's field of view cut into beams: a uniform azimuth x elevation grid (paper Sec.
// II-C), or a camera's (strided) pixels; and which beam a direction falls in.
#pragma once

#include <Eigen/Core>
#include <algorithm>
#include <array>
#include <cstddef>
#include <optional>
#include <vector>

#include "fusion/core/sensor.h"

namespace fusion {

// Angular (spec.pinhole unset): beams on a uniform azimuth x elevation grid over the sensor's
// FOV, azimuth = atan2(x, z) in azimuth_centre +- fov_h / 2, column 0 at the left (x < 0);
// elevation = atan2(-y, hypot(x, z)) in elevation_centre +- fov_v / 2, row 0 at the top.
// Pinhole: beam (col, row) holds the pixels [col s, (col + 1) s) x [row s, (row + 1) s) of the
// image (stride s, clipped to the image): a direction's column follows from x / z, its row from
// y / z, exactly as the camera projects it.
// beam index = row * cols + col. A direction exactly on the FOV edge belongs to the edge beam.
// Range along a beam is the Euclidean norm of the point (not its projection on the axis).
//
// The "elevation tangent" below is a direction's row coordinate: -y / hypot(x, z) (the tangent
// of its elevation) for angular grids, -y / z for pinhole ones; both grow upwards.
class BeamTessellation {
 public:
  explicit BeamTessellation(const SensorSpec& spec);
  [[nodiscard]] std::size_t beam_count() const;
  [[nodiscard]] int cols() const;
  [[nodiscard]] int rows() const;
  [[nodiscard]] bool pinhole() const { return pinhole_.has_value(); }
  // Beam of a direction in the sensor frame, std::nullopt outside the FOV or for a zero vector.
  // Where the grid has tangent tables (below) both coordinates are compared through tangents
  // with the beam edges' (x / z and the elevation tangent against tables: no atan2);
  // directions within ~1e-15 rad of an edge may fall on either side of it.
  [[nodiscard]] std::optional<std::size_t> BeamOf(const Eigen::Vector3d& p_sensor) const;
  // The same by the definition above (angular: two atan2 per direction; pinhole: the pixel the
  // camera projects it to): the reference.
  [[nodiscard]] std::optional<std::size_t> BeamOfByAngles(const Eigen::Vector3d& p_sensor) const;
  // Unit vector of the beam's centre line in the sensor frame.
  [[nodiscard]] Eigen::Vector3d Direction(std::size_t beam) const;
  // A unit direction inside the beam, `right` and `up` of its centre line in fractions of the
  // beam's width and height (-0.5 .. 0.5 reach its edges): angular grids step in azimuth and
  // elevation, pinhole ones on the image plane. Direction(beam) is SubDirection(beam, 0, 0).
  [[nodiscard]] Eigen::Vector3d SubDirection(std::size_t beam, double right, double up) const;
  // Grids whose azimuths stay within +-90 degrees (and every pinhole grid) have tangent tables
  // (BeamOf uses them; so does the projective render, which needs the beams a box of space
  // overlaps): the tangents of the FOV edges, and the column / row whose beam holds a direction
  // with the given azimuth tangent (x / z) / elevation tangent, clamped into the grid.
  [[nodiscard]] bool HasTangentEdges() const { return !tan_col_edges_.empty(); }
  [[nodiscard]] double TanAzimuthMin() const { return tan_col_edges_.lo(); }
  [[nodiscard]] double TanAzimuthMax() const { return tan_col_edges_.hi(); }
  [[nodiscard]] double TanElevationMin() const { return tan_row_edges_.lo(); }
  [[nodiscard]] double TanElevationMax() const { return tan_row_edges_.hi(); }
  [[nodiscard]] int ColumnOfTangent(double tan_azimuth) const;
  [[nodiscard]] int RowOfTangent(double tan_elevation) const;
  // Tangents of a column's / row's centre line (azimuth tangent, elevation tangent).
  [[nodiscard]] double ColumnCentreTangent(int col) const;
  [[nodiscard]] double RowCentreTangent(int row) const;
  // The tangent bounds of the field of view with each side moved in by `beams` beam widths (at
  // 0.5: the centre lines of the edge beams), in the order az_min, az_max, el_min, el_max.
  struct TangentBounds {
    double az_min, az_max, el_min, el_max;
  };
  [[nodiscard]] TangentBounds InsetTangents(double beams) const;
  // The same for the beams of columns [col_lo, col_hi] and rows [row_lo, row_hi] only.
  [[nodiscard]] TangentBounds InsetTangents(double beams, int col_lo, int col_hi, int row_lo,
                                            int row_hi) const;
  // Angular size of one beam (full widths); for pinhole grids the largest beam's (at the
  // image centre), an upper bound of every beam's.
  [[nodiscard]] double beam_width_h_rad() const;
  [[nodiscard]] double beam_width_v_rad() const;

 private:
  // A pinhole beam's span on the image, in continuous pixel coordinates (pixel u covers
  // [u - 0.5, u + 0.5)): its first pixel's left edge and its width in pixels.
  struct PixelSpan {
    double lo, width;
  };
  [[nodiscard]] PixelSpan SpanOf(int index, int pixels) const;
  int cols_ = 1;
  int rows_ = 1;
  double fov_h_rad_ = 0.0;
  double fov_v_rad_ = 0.0;
  double azimuth_min_rad_ = 0.0;    // the left edge
  double elevation_max_rad_ = 0.0;  // the top edge
  std::optional<PinholeIntrinsics> pinhole_;
  // An angular grid's centre directions, per column (sin, cos of the azimuth) and per row (of
  // the elevation): Direction without its trigonometry, to the last bit SubDirection's.
  std::vector<std::array<double, 2>> col_sin_cos_, row_sin_cos_;
  // Ascending edges (n + 1 values) with a uniform bucket index over them, so that the inner
  // edges below a value are counted in ~one step instead of a binary search.
  class Edges {
   public:
    Edges() = default;
    explicit Edges(std::vector<double> edges);
    [[nodiscard]] bool empty() const { return edges_.empty(); }
    [[nodiscard]] bool Contains(double v) const { return v >= edges_.front() && v <= edges_.back(); }
    [[nodiscard]] double lo() const { return edges_.front(); }
    [[nodiscard]] double hi() const { return edges_.back(); }
    [[nodiscard]] double at(int k) const { return edges_[static_cast<std::size_t>(k)]; }
    // Inner edges (all but the first and last) <= v, resp. < v; v within the edges.
    [[nodiscard]] int InnerAtOrBelow(double v) const;
    [[nodiscard]] int InnerBelow(double v) const;

   private:
    [[nodiscard]] int Start(double v) const;
    std::vector<double> edges_;
    std::vector<int> start_;  // per bucket: inner edges below its lower end
    double inverse_bucket_ = 0.0;
  };
  // Tangents of the column edges (left to right) and of the row edges (bottom to top); empty
  // when an angular FOV reaches +-90 degrees in azimuth (BeamOf then uses the angles).
  Edges tan_col_edges_;
  Edges tan_row_edges_;
};

// Inline: an octree descent asks for the beams of every block it classifies.
inline int BeamTessellation::Edges::Start(double v) const {
  const double bucket = (v - edges_.front()) * inverse_bucket_;
  const auto b = static_cast<std::size_t>(
      std::clamp(bucket, 0.0, static_cast<double>(start_.size() - 1)));
  return start_[b];
}

inline int BeamTessellation::Edges::InnerAtOrBelow(double v) const {
  const int inner = static_cast<int>(edges_.size()) - 2;
  int count = Start(v);
  while (count < inner && edges_[static_cast<std::size_t>(count) + 1] <= v) ++count;
  return count;
}

inline int BeamTessellation::Edges::InnerBelow(double v) const {
  const int inner = static_cast<int>(edges_.size()) - 2;
  int count = Start(v);
  while (count < inner && edges_[static_cast<std::size_t>(count) + 1] < v) ++count;
  return count;
}

// Always inlined: the projective render's descent calls these for every block it visits.
[[gnu::always_inline]] inline int BeamTessellation::ColumnOfTangent(double tan_azimuth) const {
  const double v = std::clamp(tan_azimuth, tan_col_edges_.lo(), tan_col_edges_.hi());
  return tan_col_edges_.InnerAtOrBelow(v);
}

[[gnu::always_inline]] inline int BeamTessellation::RowOfTangent(double tan_elevation) const {
  const double v = std::clamp(tan_elevation, tan_row_edges_.lo(), tan_row_edges_.hi());
  return (rows_ - 1) - tan_row_edges_.InnerBelow(v);
}

}  // namespace fusion
