// A sensor's field of view cut into beams: a uniform azimuth x elevation grid (paper Sec.
// II-C), and which beam a direction falls in.
#pragma once

#include <Eigen/Core>
#include <cstddef>
#include <optional>
#include <vector>

#include "fusion/core/sensor.h"

namespace fusion {

// Beams on a uniform azimuth x elevation grid over the sensor's FOV.
// azimuth = atan2(x, z) in [-fov_h/2, fov_h/2], column 0 at the left (x < 0);
// elevation = atan2(-y, hypot(x, z)) in [-fov_v/2, fov_v/2], row 0 at the top.
// beam index = row * cols + col. A direction exactly on the FOV edge belongs to the edge beam.
// Range along a beam is the Euclidean norm of the point (not its projection on the axis).
class BeamTessellation {
 public:
  explicit BeamTessellation(const SensorSpec& spec);
  [[nodiscard]] std::size_t beam_count() const;
  [[nodiscard]] int cols() const;
  [[nodiscard]] int rows() const;
  // Beam of a direction in the sensor frame, std::nullopt outside the FOV or for a zero vector.
  // For FOVs narrower than 180 degrees both angles are compared through their tangents with
  // the beam edges' (x / z and -y / hypot(x, z) against tables: no atan2); directions within
  // ~1e-15 rad of an edge may fall on either side of it.
  [[nodiscard]] std::optional<std::size_t> BeamOf(const Eigen::Vector3d& p_sensor) const;
  // The same by the definition above (two atan2 per direction): the reference.
  [[nodiscard]] std::optional<std::size_t> BeamOfByAngles(const Eigen::Vector3d& p_sensor) const;
  // Unit vector of the beam's centre line in the sensor frame.
  [[nodiscard]] Eigen::Vector3d Direction(std::size_t beam) const;
  // FOVs narrower than 180 degrees have tangent tables (BeamOf uses them; so does the
  // projective render, which needs the beams a box of space overlaps): the tangents of the FOV
  // edges, and the column / row whose beam holds a direction with the given tangent of azimuth
  // (x / z) / elevation (-y / hypot(x, z)), clamped into the grid.
  [[nodiscard]] bool HasTangentEdges() const { return !tan_col_edges_.empty(); }
  [[nodiscard]] double TanAzimuthMin() const { return tan_col_edges_.lo(); }
  [[nodiscard]] double TanAzimuthMax() const { return tan_col_edges_.hi(); }
  [[nodiscard]] double TanElevationMin() const { return tan_row_edges_.lo(); }
  [[nodiscard]] double TanElevationMax() const { return tan_row_edges_.hi(); }
  [[nodiscard]] int ColumnOfTangent(double tan_azimuth) const;
  [[nodiscard]] int RowOfTangent(double tan_elevation) const;
  // Angular size of one beam (full widths).
  [[nodiscard]] double beam_width_h_rad() const;
  [[nodiscard]] double beam_width_v_rad() const;

 private:
  int cols_ = 1;
  int rows_ = 1;
  double fov_h_rad_ = 0.0;
  double fov_v_rad_ = 0.0;
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
  // when a FOV reaches 180 degrees (BeamOf then uses the angles).
  Edges tan_col_edges_;
  Edges tan_row_edges_;
};

}  // namespace fusion
