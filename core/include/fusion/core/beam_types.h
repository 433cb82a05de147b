// The plain types of a beam grid: its options, one reading along a beam, what an integration
// did, and where a beam's information lies. No behaviour beyond checking the options; everything
// beam-related includes it.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>

namespace fusion {

enum class BeamRepresentation { kDense, kUnrolledLinkedList };

struct BeamGridOptions {
  static constexpr double kDefaultCellSizeM = 0.001;
  // Cell lengths IsValid accepts. Finer than 0.1 mm a cell resolves nothing a range sensor
  // measures (sigma is millimetres) and an 8 m beam has 80 000 of them; coarser than 1 m a cell
  // outgrows any voxel it is rendered into.
  static constexpr double kMinCellSizeM = 1e-4;
  static constexpr double kMaxCellSizeM = 1.0;
  // prior_cell_occupancy: derive it from prior_reference_length_m.
  static constexpr double kPriorFromReferenceLength = -1.0;
  static constexpr double kDefaultPriorReferenceLengthM = 0.05;
  static constexpr BeamRepresentation kDefaultRepresentation =
      BeamRepresentation::kUnrolledLinkedList;

  double cell_size_m = kDefaultCellSizeM;
  // Prior occupancy of each cell. Default (negative): chosen so that a run of cells
  // prior_reference_length_m long has prior occupancy 0.5, i.e. a map voxel of that size
  // starts unknown; p0 = 1 - 0.5^(cell_size / reference_length).
  double prior_cell_occupancy = kPriorFromReferenceLength;
  double prior_reference_length_m = kDefaultPriorReferenceLengthM;
  BeamRepresentation representation = kDefaultRepresentation;

  // Change detection (docs/mapping.md, "A world that changes"). Once some reading since the beam
  // (re)started found at least half of the beam's p(B) on the cells its forward model can
  // explain it from (the outcome's ROI: mu +- Delta sigma, bias included), a reading is
  // surprising when that mass is below change_min_mass: the posterior calls it nearly
  // impossible but for the outlier floor. A cloud is one observation of a beam: it surprises the
  // beam when more than half of the beam's readings in it are surprising. Every reading is
  // applied; change_run surprising clouds in a row restart the beam at its prior after the cloud
  // and apply a reading of each earlier cloud of the run and all of the last again (0: off).
  // Under the model's own noise a reading is surprising about as often as it falls outside
  // Delta sigma (0.27 % at 3 sigma), so 3 in a row happen ~2e-8 times per beam and cloud; a
  // surface moved by 2 Delta sigma trips every cloud. The ROI mass comes out of the update's
  // own loop: on costs ~4 % of the integrator's instructions (BENCHMARKS.md).
  static constexpr std::uint32_t kDefaultChangeRun = 3;
  static constexpr double kDefaultChangeMinMass = 1e-3;
  std::uint32_t change_run = kDefaultChangeRun;
  double change_min_mass = kDefaultChangeMinMass;

  // True if a beam grid can be built with these options; else false, and *why (if not null)
  // says what is wrong, starting with the field's name ("cell_size_m must lie in ...").
  [[nodiscard]] bool IsValid(std::string* why = nullptr) const;
};

// What happened to one cloud: every point is accounted for in exactly one counter.
struct IntegrationStats {
  std::size_t updated = 0;             // range readings applied
  std::size_t beyond_range = 0;        // beyond-range readings applied (evidence for B_{N+1})
  std::size_t missing = 0;             // NaN / zero points: no information, beam untouched
  std::size_t rejected_nonfinite = 0;  // inf or mixed NaN coordinates
  std::size_t rejected_outside_fov = 0;
  std::size_t rejected_outside_map = 0;  // world position beyond the map's keys (SensorPeriods)
  // Not a point count: beams restarted because the world changed (BeamGridOptions::change_run).
  std::size_t changes_detected = 0;
};

// Where a beam's information lies, from a start range on (BeamGrid::Profile).
struct BeamProfile {
  // Range (cell edge) where the first-hit mass starts: the first cell whose p(m) exceeds
  // free_ratio times the prior; +infinity if no cell does (the beam is free to its end).
  double mass_begin_m = 0.0;
  // InformationEndM(beam, from_m, tail_fraction).
  double info_end_m = 0.0;
  // The free zone [from_m, min(mass_begin_m, beam end)): its cumulative hazard against the
  // prior's over the same length, as log-odds (about the evidence a voxel-long segment of the
  // zone carries, logit(p) - logit(prior)); -infinity if the zone is empty.
  double free_log_odds = 0.0;
  // InformationEndM(beam, from_m, 0.5): the first hit is as likely before as after it (where
  // the beam's surface is); +infinity if the beam more likely sees through.
  double median_m = 0.0;
};

// One reading along a beam.
struct Reading {
  enum class Kind : std::uint8_t { kRange, kBeyondRange, kMissing };
  Kind kind = Kind::kMissing;
  double range_m = 0.0;
};

}  // namespace fusion
