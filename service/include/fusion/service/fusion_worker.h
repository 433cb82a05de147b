// The fusion worker: two threads between the ingest queues and the published map.
//
//  - The integrator drains the ingest queues into each sensor's open period (core's
//    SensorPeriods). A cloud from beyond the pose tolerance seals the period and hands it to the
//    renderer; the integrator goes on at once with a new period, never waiting for the render of
//    an older one. When a sensor already has kMaxSealedPeriods waiting, its clouds are merged
//    into the open period instead (counted as `merged`): evidence is never thrown away. With
//    reliable ingest (wait_for_renderer) the integrator waits for room instead, so a replayed
//    recording is mapped exactly as taken.
//  - The renderer takes sealed periods in order (render, commit into the map's history), and when
//    none is waiting renders open periods with new frames: a period's first frame at once (a
//    moving sensor's frame is then in the map before the next one seals it, and that render
//    serves the commit), later frames every render_interval. A cloud for a period being rendered
//    waits for that render only if it would go into that period; one that seals it does not.
//    After each step it publishes the map: core's WorldMap hands out a tree that is never
//    written again and its change set, without copying the map.
#pragma once

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "fusion/core/sensor_periods.h"
#include "fusion/core/status.h"
#include "fusion/core/world_map.h"
#include "fusion/service/conversions.h"
#include "fusion/service/ingest_queues.h"
#include "fusion/service/map_snapshot.h"
#include "fusion/service/metrics.h"
#include "fusion/service/rejection_log.h"

namespace fusion::service {

struct WorkerOptions {
  WorldMapOptions map;
  StateThresholds thresholds;
  // Shortest time between two renders of one sensor's open period (0: as soon as the renderer
  // is free). Sealed periods are rendered at once.
  std::chrono::milliseconds render_interval{0};
  // Nice value of the worker's threads and its render threads (0: as the process).
  int nice = 10;
  // Reliable ingest: instead of merging clouds while the renderer is behind, the integrator
  // waits for it (the ingest queues then fill and DDS flow control slows the writers).
  bool wait_for_renderer = false;
  // Step durations and latency to observe (metrics.h); all null: nothing is measured.
  WorkerHistograms histograms;
};

// One beam of a sensor's beam grid, for inspection.
struct BeamInspection {
  std::size_t beam = 0;
  double cell_size_m = 0.0;
  Eigen::Vector3d direction_sensor = Eigen::Vector3d::UnitZ();
  std::vector<double> first_hit;       // p(B_1..B_{N+1})
  std::vector<double> cell_occupancy;  // p(m_1..m_N)
  bool touched = false;
};

enum class BeamLookup { kOk, kUnknownSensor, kBeamOutOfRange };

class FusionWorker {
 public:
  // Sealed periods a sensor may have waiting for the renderer before clouds are merged.
  static constexpr std::size_t kMaxSealedPeriods = 2;
  // Clouds the integrator may hold while their sensor's open period is being rendered, going on
  // with other sensors' clouds; beyond, it waits for the render (the queues' limits hold then).
  static constexpr std::size_t kMaxHeldClouds = 8;

  FusionWorker(WorkerOptions options, std::vector<SensorSetup> sensors, IngestQueues* queues,
               SnapshotHub* hub);
  ~FusionWorker();
  FusionWorker(const FusionWorker&) = delete;
  FusionWorker& operator=(const FusionWorker&) = delete;

  // `history` (may be null) is a map loaded from disk: the committed history to go on from.
  // Publishes the first version and starts the threads.
  [[nodiscard]] Status Start(std::unique_ptr<octomap::OcTree> history);
  // Integrates what is still queued, renders and commits everything, publishes, stops.
  void Stop();

  // Clears the map and every beam grid; returns the new version. Waits for the current
  // integration and render steps.
  std::uint64_t Reset();
  // Forgets a box of the map (world frame; docs/service.md, ClearBox): every sensor's open
  // period is sealed and, with those waiting, committed, so that all evidence integrated before
  // the call is in the history; then the box is removed from it and the map is published.
  // Clouds integrated meanwhile start new periods. Sets *voxels to the voxels forgotten; returns
  // the new version.
  std::uint64_t ClearBox(const Eigen::AlignedBox3d& box_world, std::uint64_t* voxels);
  // A camera configured without intrinsics (SensorSetup::intrinsics_from_camera_info) gets its
  // beams: `spec` (SpecFromCameraInfo) makes its beam grid, and its clouds integrate from then
  // on (before, they are not integrated). An error when the sensor does not wait for them.
  [[nodiscard]] Status DefineSensor(const std::string& sensor_id, const SensorSpec& spec);
  // The sensor's spec as its beam grid has it (a waiting camera's: without beams).
  [[nodiscard]] std::optional<SensorSpec> SpecOf(const std::string& sensor_id) const;
  // beam: an index, or row/col when std::nullopt. The open period's beam grid.
  BeamLookup InspectBeam(const std::string& sensor_id, std::optional<std::size_t> beam,
                         std::size_t row, std::size_t col, BeamInspection* out) const;

  [[nodiscard]] std::uint64_t renders() const { return renders_.load(); }
  [[nodiscard]] std::uint64_t integrated() const { return integrated_.load(); }
  // Clouds whose evidence the published map holds (counted after it is published).
  [[nodiscard]] std::uint64_t in_map() const { return in_map_.load(); }

 private:
  struct Lane;
  struct Sealed {
    Lane* lane;
    std::unique_ptr<Period> period;
  };

  // Start's part under map_mutex_: the map, the sensors' lanes, the first publication.
  [[nodiscard]] Status StartLocked(std::unique_ptr<octomap::OcTree> history);
  // Under map_mutex_: the sensor in the map and its periods' beam grid.
  [[nodiscard]] Status AddBeamGridLocked(Lane& lane, const SensorSpec& spec);
  void IntegratorLoop();
  void RendererLoop();
  // Integrates the clouds of *held in order, leaving in it those that must wait for a render
  // of their sensor's open period (and the same sensor's after them); with `wait`, waits.
  void IntegrateHeld(std::deque<Cloud>* held, bool wait);
  // Integrates `cloud` (or counts it rejected); returns false without waiting when the renderer
  // reads the period it would join and `wait` is false: the renderer wakes the integrator then.
  bool Integrate(const Cloud& cloud, bool wait);
  void ObserveIntegration(Lane& lane, const Cloud& cloud,
                          std::chrono::steady_clock::time_point start, MapStatus status);
  // One renderer step (sealed period first, else an open period); false if there was nothing
  // to do.
  bool RenderStep();
  // Forgetting (map.forget_half_life_s): lets the time since the last step pass over the map's
  // history when it is due; false if it was not.
  bool ForgetStep(std::chrono::steady_clock::time_point now);
  // Under work_mutex_: the lane's open period may be rendered now (its first frame waits for
  // nothing; later ones for render_interval after the last render of it).
  [[nodiscard]] bool OpenRenderDue(const Lane& lane, std::chrono::steady_clock::time_point now) const;
  void CommitSealed(Sealed sealed);
  bool RenderOpen(Lane& lane);
  void PublishLocked();
  void ObserveQueryable();  // under map_mutex_, after a publication
  Lane* LaneOf(const std::string& sensor_id) const;

  WorkerOptions options_;
  RenderOptions render_options_;
  std::vector<SensorSetup> sensors_;
  IngestQueues* queues_;
  RejectionLog rejections_{std::chrono::seconds(1)};  // clouds that reach no beam grid
  SnapshotHub* hub_;
  std::vector<std::unique_ptr<Lane>> lanes_;

  std::mutex map_mutex_;  // the renderer's steps, Reset; guards map_
  std::unique_ptr<WorldMap> map_;
  std::uint64_t published_version_ = 0;
  std::chrono::steady_clock::time_point last_forget_;  // under map_mutex_

  std::mutex work_mutex_;  // guards sealed_ and the wake-up of the renderer
  std::condition_variable work_cv_;
  std::condition_variable room_cv_;  // a sealed period was committed
  std::deque<Sealed> sealed_;
  bool integrator_done_ = false;

  std::atomic<bool> stop_{false};
  std::thread integrator_;
  std::thread renderer_;
  std::atomic<std::uint64_t> renders_{0};
  std::atomic<std::uint64_t> integrated_{0};
  std::atomic<std::uint64_t> in_map_{0};
};

}  // namespace fusion::service
