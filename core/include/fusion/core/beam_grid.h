// Per-sensor beam grid: a fixed angular tessellation of the sensor's field of view, each beam
// a list of range cells updated with the forward model (paper Sec. II-C, IV-A).
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <vector>

#include <Eigen/Core>

#include "fusion/core/sensor.h"

namespace fusion {

// Beams on a uniform azimuth x elevation grid over the sensor's FOV.
// azimuth = atan2(x, z) in [-fov_h/2, fov_h/2], column 0 at the left (x < 0);
// elevation = atan2(-y, hypot(x, z)) in [-fov_v/2, fov_v/2], row 0 at the top.
// beam index = row * cols + col.
class BeamTessellation {
 public:
  explicit BeamTessellation(const SensorSpec& spec);
  [[nodiscard]] std::size_t beam_count() const;
  [[nodiscard]] int cols() const;
  [[nodiscard]] int rows() const;
  // Beam of a direction in the sensor frame, std::nullopt outside the FOV or for a zero vector.
  [[nodiscard]] std::optional<std::size_t> BeamOf(const Eigen::Vector3d& p_sensor) const;
  // Unit vector of the beam's centre line in the sensor frame.
  [[nodiscard]] Eigen::Vector3d Direction(std::size_t beam) const;
  // Angular size of one beam (full widths).
  [[nodiscard]] double beam_width_h_rad() const;
  [[nodiscard]] double beam_width_v_rad() const;
};

enum class BeamRepresentation { kDense, kUnrolledLinkedList };

struct BeamGridOptions {
  double cell_size_m = 0.001;
  // Prior occupancy of each cell. Default (negative): chosen so that a run of cells
  // prior_reference_length_m long has prior occupancy 0.5, i.e. a map voxel of that size
  // starts unknown; p0 = 1 - 0.5^(cell_size / reference_length).
  double prior_cell_occupancy = -1.0;
  double prior_reference_length_m = 0.05;
  BeamRepresentation representation = BeamRepresentation::kUnrolledLinkedList;
};

// What happened to one cloud: every point is accounted for in exactly one counter.
struct IntegrationStats {
  std::size_t updated = 0;        // range readings applied
  std::size_t beyond_range = 0;   // beyond-range readings applied (evidence for B_{N+1})
  std::size_t missing = 0;        // NaN / zero points: no information, beam untouched
  std::size_t rejected_nonfinite = 0;  // inf or mixed NaN coordinates
  std::size_t rejected_outside_fov = 0;
};

// One reading along a beam.
struct Reading {
  enum class Kind : std::uint8_t { kRange, kBeyondRange, kMissing };
  Kind kind = Kind::kMissing;
  double range_m = 0.0;
};

class BeamGrid {
 public:
  BeamGrid(const SensorSpec& spec, const BeamGridOptions& options);
  ~BeamGrid();
  BeamGrid(BeamGrid&&) noexcept;
  BeamGrid& operator=(BeamGrid&&) noexcept;

  [[nodiscard]] const SensorSpec& spec() const;
  [[nodiscard]] const BeamGridOptions& options() const;
  [[nodiscard]] const BeamTessellation& tessellation() const;
  [[nodiscard]] std::size_t cells_per_beam() const;  // N

  // Applies one cloud of points in the sensor frame. points_xyz holds 3 floats per point.
  // beyond_range (optional, same length as the point count, may be empty) marks points whose
  // direction is valid but whose return lies beyond r_max.
  IntegrationStats Integrate(const float* points_xyz, std::size_t point_count,
                             const std::vector<std::uint8_t>& beyond_range = {});
  // Applies one reading to one beam (Eq. 11).
  void Update(std::size_t beam, const Reading& reading);

  // p(B_1..B_N, B_{N+1}) of one beam (N + 1 values, summing to 1).
  [[nodiscard]] std::vector<double> FirstHitProbabilities(std::size_t beam) const;
  // p(m_1..m_N) of one beam (Eq. 8; cells with no information keep their previous value).
  [[nodiscard]] std::vector<double> CellProbabilities(std::size_t beam) const;
  // Occupancy of consecutive range intervals of one beam: boundaries_m (ascending, k+1 values,
  // in [0, N * cell_size]) gives k intervals; out[j] = P(some cell in interval j occupied |
  // every cell before it free) = 1 - S(b_{j+1}) / S(b_j), where S(b) is the p(B) mass of the
  // cells at and after b (B_{N+1} included). Where S(b_j) == 0 (no information) the
  // interval's prior occupancy is returned. Boundaries are rounded to cell edges.
  void IntervalOccupancy(std::size_t beam, const std::vector<double>& boundaries_m,
                         std::vector<double>* out) const;
  // Prior occupancy of an interval of the given length (what an untouched beam reports).
  [[nodiscard]] double PriorOccupancy(double length_m) const;
  // True if the beam has received at least one reading since construction or Reset.
  [[nodiscard]] bool Touched(std::size_t beam) const;

  void Reset();
  [[nodiscard]] std::size_t MemoryBytes() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace fusion
