// The fusion worker: one thread that drains the ingest queues into core's WorldMap, renders at
// the configured cadence and publishes each new map version as an immutable snapshot.
//
// The published map is, per voxel, the fusion rule applied to the snapshot loaded at start
// (the "base", committed history of an earlier run) and WorldMap's fused map.
#pragma once

#include <atomic>
#include <chrono>
#include <cstdint>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "fusion/core/world_map.h"
#include "fusion/service/conversions.h"
#include "fusion/service/ingest_queues.h"
#include "fusion/service/map_snapshot.h"

namespace fusion::service {

struct WorkerOptions {
  WorldMapOptions map;
  StateThresholds thresholds;
  std::chrono::milliseconds render_interval{200};
  // Nice value of the worker thread and its render threads (0: as the process).
  int nice = 10;
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
  FusionWorker(WorkerOptions options, std::vector<SensorSetup> sensors, IngestQueues* queues,
               SnapshotHub* hub);
  ~FusionWorker();
  FusionWorker(const FusionWorker&) = delete;
  FusionWorker& operator=(const FusionWorker&) = delete;

  // `base` (may be null) is a map loaded from disk; publishes the first version and starts
  // the thread.
  bool Start(std::unique_ptr<octomap::OcTree> base, std::string* error);
  // Integrates what is still queued, renders, publishes, stops the thread.
  void Stop();

  // Clears the map, the base and every beam grid; returns the new version. Waits for the
  // worker's current integration or render step.
  std::uint64_t Reset();
  // beam: an index, or row/col when std::nullopt.
  BeamLookup InspectBeam(const std::string& sensor_id, std::optional<std::size_t> beam,
                         std::size_t row, std::size_t col, BeamInspection* out) const;

  [[nodiscard]] std::uint64_t renders() const { return renders_.load(); }
  [[nodiscard]] std::uint64_t integrated() const { return integrated_.load(); }
  // Clouds integrated into the published map version (counted after it is published).
  [[nodiscard]] std::uint64_t in_map() const { return in_map_.load(); }

 private:
  void Loop();
  void IntegrateLocked(const Cloud& cloud);
  void RenderAndPublishLocked();
  void PublishLocked(std::vector<octomap::OcTreeKey> changed, bool reset);
  void RebuildMapLocked();
  // published_ = base fused with the live map, from scratch.
  void RebuildPublishedLocked();
  // Fused value of one key from base and live map; std::nullopt: no information.
  std::optional<float> FusedLogOddsLocked(const octomap::OcTreeKey& key) const;

  WorkerOptions options_;
  std::vector<SensorSetup> sensors_;
  IngestQueues* queues_;
  SnapshotHub* hub_;

  mutable std::mutex map_mutex_;  // guards everything below
  std::unique_ptr<WorldMap> map_;
  std::unique_ptr<octomap::OcTree> base_;
  std::unique_ptr<octomap::OcTree> published_;
  std::uint64_t version_offset_ = 0;
  std::uint64_t rendered_map_version_ = 0;
  bool dirty_ = false;

  std::atomic<bool> stop_{false};
  std::thread thread_;
  std::atomic<std::uint64_t> renders_{0};
  std::atomic<std::uint64_t> integrated_{0};
  std::atomic<std::uint64_t> in_map_{0};
};

}  // namespace fusion::service
