// Per-sensor beam grid: a fixed angular tessellation of the sensor's field of view
// (beam_tessellation.h), each beam a list of range cells updated with the forward model
// (paper Sec. II-C, IV-A).
#pragma once

#include <Eigen/Core>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <vector>

#include "fusion/core/beam_tessellation.h"
#include "fusion/core/beam_types.h"
#include "fusion/core/sensor.h"

namespace fusion {

// The cell edge a range rounds to in a beam of n cells of cell_size_m (BeamGrid::CellOf; inline
// for a render, which asks for every crossing): the nearest edge, NaN and negatives to 0, at
// most n. The cast after the clamps rounds as std::round does for these non-negative values.
[[nodiscard]] inline std::uint32_t CellOfRange(double range_m, double cell_size_m, std::size_t n) {
  const double c = range_m / cell_size_m;
  if (!(c >= 0.0)) return 0;
  const auto cells = static_cast<double>(n);
  if (c >= cells) return static_cast<std::uint32_t>(cells);
  return static_cast<std::uint32_t>(c + 0.5);
}

class BeamGrid {
 public:
  // Throws std::invalid_argument for an invalid spec (ValidateSensorSpec) or options.
  BeamGrid(const SensorSpec& spec, const BeamGridOptions& options);
  ~BeamGrid();
  BeamGrid(BeamGrid&&) noexcept;
  BeamGrid& operator=(BeamGrid&&) noexcept;

  [[nodiscard]] const SensorSpec& spec() const;
  [[nodiscard]] const BeamGridOptions& options() const;
  [[nodiscard]] const BeamTessellation& tessellation() const;
  [[nodiscard]] std::size_t cells_per_beam() const;  // N
  [[nodiscard]] std::size_t beam_count() const;
  // p0 actually used (options.prior_cell_occupancy resolved).
  [[nodiscard]] double prior_cell_occupancy() const;
  // Cells below this index are blind (range < r_min): p(r | B_i) = 0, treat as unknown.
  [[nodiscard]] std::size_t first_visible_cell() const;
  // Readings above this range are the outcome `beyond` (Algorithm III.1 line 1).
  [[nodiscard]] double r_limit_m() const;

  // Applies one cloud of points in the sensor frame. points_xyz holds 3 floats per point.
  // beyond_range (optional, same length as the point count, may be empty) marks points whose
  // direction is valid but whose return lies beyond r_max.
  // Per point: all-NaN or (0, 0, 0) -> missing (no information); any inf or a NaN mixed with
  // numbers -> rejected_nonfinite; direction outside the FOV -> rejected_outside_fov; marked
  // beyond or range > r_limit -> beyond_range (evidence for B_{N+1}); else updated. Several
  // points in one beam are several samples, applied in order. Throws std::invalid_argument
  // (before touching any beam) if points_xyz is null with point_count > 0 or beyond_range is
  // neither empty nor point_count long.
  IntegrationStats Integrate(const float* points_xyz, std::size_t point_count,
                             const std::vector<std::uint8_t>& beyond_range = {});
  // Applies readings[b] to beam b for every beam (an organised frame, one reading per beam);
  // readings.size() must equal beam_count() (std::invalid_argument otherwise). Faster than
  // beam_count() calls to Update: beams are prefetched ahead. Returns the counts (points
  // are never outside the FOV here; invalid ranges count as missing).
  IntegrationStats UpdateEachBeam(const std::vector<Reading>& readings);
  // Applies one reading to one beam (Eq. 11). kMissing, NaN, inf or negative ranges carry no
  // information and leave the beam untouched (returns false). Throws std::out_of_range for a
  // beam index >= beam_count(). Returns true if the beam was updated.
  bool Update(std::size_t beam, const Reading& reading);

  // p(B_1..B_N, B_{N+1}) of one beam (N + 1 values, summing to 1).
  [[nodiscard]] std::vector<double> FirstHitProbabilities(std::size_t beam) const;
  // p(m_1..m_N) of one beam (Eq. 8; cells with no information keep their previous value).
  // Cells with no information report the prior: the cached p(B) is the only state kept.
  [[nodiscard]] std::vector<double> CellProbabilities(std::size_t beam) const;
  // Occupancy of consecutive range intervals of one beam: boundaries_m (ascending, k+1 values,
  // in [0, N * cell_size]) gives k intervals; out[j] = P(some cell in interval j occupied |
  // every cell before it free) = 1 - S(b_{j+1}) / S(b_j), where S(b) is the p(B) mass of the
  // cells at and after b (B_{N+1} included). Where S(b_j) == 0 (no information) the
  // interval's prior occupancy is returned. Boundaries are rounded to cell edges.
  void IntervalOccupancy(std::size_t beam, const std::vector<double>& boundaries_m,
                         std::vector<double>* out) const;
  // S(c) for every cell c in [first, last] (clamped to [0, N]) of one beam into *tails, and S(0)
  // (the beam's whole mass) into *total, in one walk of the beam: for a renderer that asks
  // IntervalOccupancy many times about one stretch of a beam (IntervalOccupancyOfCells).
  void TailMassSpan(std::size_t beam, std::uint32_t first, std::uint32_t last,
                    std::vector<double>* tails, double* total) const;
  // S(c) for `count` ascending cells c (each at most N) of one beam into out[], in one walk:
  // IntervalOccupancy without its boundaries' rounding (a renderer has the cells already).
  void TailMasses(std::size_t beam, const std::uint32_t* cells, std::size_t count,
                  double* out) const;
  // What IntervalOccupancy reports for the cells [a, b) from S(a), S(b) and the beam's total.
  [[nodiscard]] double IntervalOccupancyOfCells(double tail_a, double tail_b, double total,
                                                std::uint32_t cells) const;
  // The cell IntervalOccupancy rounds a boundary to (NaN and negatives to 0, at most N).
  [[nodiscard]] std::uint32_t CellOf(double range_m) const;
  // Where a ray from from_m on stops carrying information: the range (cell edge) of the first
  // cell after from_m whose tail mass S is below fraction * S(from_m), i.e. where the chance
  // that the beam's first hit still lies ahead has fallen below `fraction`. +infinity if
  // S never falls that low (the beam may see through).
  [[nodiscard]] double InformationEndM(std::size_t beam, double from_m, double fraction) const;
  // Both ends of the beam's first-hit mass and the evidence of its free zone, in one walk of
  // the beam (docs/mapping.md, "Projective render"). free_ratio in (0, 1).
  [[nodiscard]] BeamProfile Profile(std::size_t beam, double from_m, double tail_fraction,
                                    double free_ratio) const;
  // Prior occupancy of an interval of the given length (what an untouched beam reports).
  [[nodiscard]] double PriorOccupancy(double length_m) const;
  // True if the beam has received at least one reading since construction or Reset.
  [[nodiscard]] bool Touched(std::size_t beam) const;

  void Reset();
  // A grid of the same sensor and options, every beam untouched, sharing this one's read-only
  // per-sensor tables (the forward model's), so it costs only its beams.
  [[nodiscard]] std::unique_ptr<BeamGrid> EmptyCopy() const;
  // Bytes of this grid's beams and of the tables it shares with its copies.
  [[nodiscard]] std::size_t MemoryBytes() const;

 private:
  struct Impl;
  explicit BeamGrid(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace fusion
