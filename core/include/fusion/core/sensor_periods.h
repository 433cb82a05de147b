// The integration side of a sensor's map life cycle (DESIGN.md, "Map life cycle"): clouds
// accumulate in the beam grid of the sensor's open period while its pose stays within a
// tolerance of the pose the period started at; a cloud from beyond it seals the period (which
// is then rendered and committed into the map) and opens a new one at its own pose. A cloud
// taken within the tolerance, but not at the period's pose, has its points moved into the
// period's sensor frame (T_period^-1 T_cloud): it is mapped where it was measured, and only
// its rays' origin is approximated.
//
// A caller that cannot render as fast as periods are sealed may refuse to seal: the cloud is
// then merged into the open period the same way, so no evidence is thrown away.
//
// Thread-compatible: one thread integrates; a sealed period is handed over whole.
#pragma once

#include <Eigen/Geometry>
#include <cstdint>
#include <memory>
#include <vector>

#include "fusion/core/beam_grid.h"
#include "fusion/core/sensor.h"

namespace fusion {

enum class MapStatus {
  kOk,
  kUnknownSensor,
  kDuplicateSensor,
  kInvalidPose,      // non-finite translation or a non-rotation matrix
  kInvalidArgument,  // e.g. null points with a non-zero count
  kOutsideMap,       // the sensor's position lies beyond the map's keys (InsideMap)
};
[[nodiscard]] const char* MapStatusName(MapStatus status);

// True if T is finite and its linear part a rotation (within 1e-3).
[[nodiscard]] bool ValidPose(const Eigen::Isometry3d& T);

struct Period {
  std::unique_ptr<BeamGrid> grid;
  Eigen::Isometry3d T_world_sensor = Eigen::Isometry3d::Identity();
  std::uint64_t frames = 0;         // clouds integrated
  std::uint64_t merged_frames = 0;  // of those, taken from outside the tolerance
  std::uint64_t sequence = 0;       // periods of the sensor are numbered from 1
};

struct PeriodIntegration {
  IntegrationStats stats;
  bool merged = false;  // the pose left the tolerance, the cloud went into the open period
};

class SensorPeriods {
 public:
  // map_resolution_m > 0: poses and points are checked against the map's key range at that
  // resolution (InsideMap); 0: not checked.
  SensorPeriods(const SensorSpec& spec, const BeamGridOptions& grid_options,
                double pose_tolerance_m, double pose_tolerance_rad, double map_resolution_m = 0.0);

  // Applies one cloud (sensor frame, 3 floats per point; beyond_range as BeamGrid::Integrate)
  // taken at T_world_sensor. If the pose left the tolerance of a non-empty open period and
  // may_seal, that period is moved to *sealed and a new one opened; without may_seal the cloud
  // is merged. Statuses for a bad pose, a pose outside the map or bad arguments (nothing is
  // touched then). Points whose world position lies outside the map are left out and counted
  // (IntegrationStats::rejected_outside_map).
  MapStatus Integrate(const Eigen::Isometry3d& T_world_sensor, const float* points_xyz,
                      std::size_t point_count, const std::vector<std::uint8_t>& beyond_range,
                      bool may_seal, PeriodIntegration* result, std::unique_ptr<Period>* sealed);

  // True if Integrate with may_seal would seal the open period for a cloud taken at
  // T_world_sensor: the pose is valid, inside the map, and beyond the tolerance of a non-empty
  // open period. Such an integration leaves the open period's grid untouched (it goes to
  // *sealed whole), so it may run while another thread still reads that grid.
  [[nodiscard]] bool WouldSeal(const Eigen::Isometry3d& T_world_sensor) const;
  // The open period (frames == 0: nothing integrated since it opened).
  [[nodiscard]] const Period& open() const { return *open_; }
  // Seals the open period now (std::nullptr if it is empty) and opens an empty one.
  [[nodiscard]] std::unique_ptr<Period> Seal();
  // Gives back a sealed period whose grid is no longer needed: its memory is reused.
  void Recycle(std::unique_ptr<Period> period);
  // Empties the open period (a map reset).
  void Reset();
  [[nodiscard]] const SensorSpec& spec() const { return spec_; }
  // A period's beam grid covers the sensor's field of view grown by the pose tolerance's angle
  // and the angle its translation subtends at kMarginRangeM (or r_min, if farther): a frame
  // taken within the tolerance keeps the readings it takes just outside the period's first
  // view. The sensor's beam (col, row) is the grid's (col + cols, row + rows).
  static constexpr double kMarginRangeM = 1.0;
  [[nodiscard]] const BeamMargin& beam_margin() const { return margin_; }
  [[nodiscard]] std::size_t MemoryBytes() const;

 private:
  [[nodiscard]] bool Moved(const Eigen::Isometry3d& T_world_sensor) const;
  // `points` (in the frame T_world_frame) without the range readings outside the map (made
  // NaN, counted); `points` itself when none can be.
  const float* InsideMapOnly(const Eigen::Isometry3d& T_world_frame, const float* points,
                             std::size_t point_count, const std::vector<std::uint8_t>& beyond_range,
                             std::size_t* outside);
  // `points` (taken at T_world_cloud) in the open period's sensor frame, in moved_.
  const float* IntoOpenFrame(const Eigen::Isometry3d& T_world_cloud, const float* points,
                             std::size_t point_count);
  std::unique_ptr<Period> NewPeriod();

  SensorSpec spec_;
  BeamMargin margin_;
  SensorSpec grid_spec_;  // spec_ grown by margin_
  BeamGridOptions grid_options_;
  double pose_tolerance_m_;
  double pose_tolerance_rad_;
  std::unique_ptr<Period> open_;
  std::unique_ptr<Period> spare_;  // a recycled period, grid reset
  std::uint64_t sequence_ = 0;
  double map_resolution_m_;
  std::vector<float> moved_;   // points of a cloud in the open period's frame (IntoOpenFrame)
  std::vector<float> inside_;  // points without those outside the map
};

}  // namespace fusion
