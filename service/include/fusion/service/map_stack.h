// fusiond without its transports: the configured sensors, the bounded ingest queues, the fusion
// worker, the published snapshots, persistence and the heavy-query pool, wired together as the
// FusionMap handlers read them (ServiceState). FusionServer adds DDS ingest and the gRPC server
// on top; handler tests drive a MapService over an in-process channel against one of these.
#pragma once

#include <functional>
#include <memory>
#include <string>

#include "fusion/service/map_service.h"
#include "fusion/v1/config.pb.h"

namespace fusion::service {

class MapStack {
 public:
  // `on_persistence_health` is told when snapshot writes start failing (false) or recover.
  MapStack(fusion::v1::ServiceConfig config, std::function<void(bool)> on_persistence_health);
  ~MapStack();
  MapStack(const MapStack&) = delete;
  MapStack& operator=(const MapStack&) = delete;

  // Converts the configuration (it must have passed ValidateConfig), loads the last snapshot
  // (a corrupt one is set aside and logged, not an error), starts the worker and the
  // persister. An error when something cannot start.
  [[nodiscard]] Status Start();
  // Before Start: what the fusion worker observes (metrics.h; default: nothing).
  void set_worker_histograms(const WorkerHistograms& histograms) { histograms_ = histograms; }

  // Shutdown, in three steps around the transports: BeginShutdown refuses new calls and ends the
  // update streams; StopQueries joins the heavy-query pool (after the gRPC server has stopped:
  // no call may finish later); Finish drains the queues into the map and writes the final
  // snapshot: an error if it could not be written.
  void BeginShutdown();
  void StopQueries();
  [[nodiscard]] Status Finish();

  [[nodiscard]] ServiceState* state() { return &state_; }
  [[nodiscard]] IngestQueues* queues() { return state_.queues; }
  [[nodiscard]] const WorldMapOptions& map_options() const { return map_options_; }

 private:
  [[nodiscard]] Status ConvertConfig();
  [[nodiscard]] Status LoadLastSnapshot(std::unique_ptr<octomap::OcTree>* base);

  fusion::v1::ServiceConfig config_;
  std::function<void(bool)> on_persistence_health_;
  ServiceState state_;
  WorldMapOptions map_options_;
  WorkerHistograms histograms_;
  std::unique_ptr<IngestQueues> queues_;
  std::unique_ptr<SnapshotHub> hub_;
  std::unique_ptr<FusionWorker> worker_;
  std::unique_ptr<Persister> persister_;
  // Gives back what the expensive calls freed, after each of them (docs/service.md,
  // "Overload"); declared before the pool, which calls it.
  HeapTrimmer heap_trimmer_{std::chrono::milliseconds(500)};
  std::unique_ptr<QueryPool> heavy_pool_;
  bool finished_ = false;
};

}  // namespace fusion::service
