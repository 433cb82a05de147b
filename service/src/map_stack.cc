#include "fusion/service/map_stack.h"

#include <spdlog/spdlog.h>

#include "fusion/service/persistence.h"

namespace fusion::service {

MapStack::MapStack(fusion::v1::ServiceConfig config,
                   std::function<void(bool)> on_persistence_health)
    : config_(std::move(config)), on_persistence_health_(std::move(on_persistence_health)) {}

MapStack::~MapStack() {
  BeginShutdown();
  StopQueries();
  (void)Finish();
}

bool MapStack::ConvertConfig(std::string* error) {
  state_.config = config_;
  std::vector<std::pair<std::string, std::size_t>> queue_specs;
  for (int i = 0; i < config_.sensors_size(); ++i) {
    std::string detail;
    auto setup = SensorSetupFromConfig(config_.sensors(i), &detail);
    if (!setup) {
      *error = "sensors[" + std::to_string(i) + "]." + detail;
      return false;
    }
    queue_specs.emplace_back(setup->id, setup->queue_depth);
    state_.sensors.push_back(std::move(*setup));
  }
  std::string detail;
  const auto map_options = WorldMapOptionsFromConfig(config_.map(), &detail);
  if (!map_options) {
    *error = "map." + detail;
    return false;
  }
  map_options_ = *map_options;
  state_.thresholds = ThresholdsFromConfig(config_.map());
  queues_ = std::make_unique<IngestQueues>(
      queue_specs, std::size_t{config_.ingest().max_queued_mb()} << 20);
  state_.queues = queues_.get();
  return true;
}

// The last snapshot, if any: loaded into *base, or set aside when corrupt.
bool MapStack::LoadLastSnapshot(std::unique_ptr<octomap::OcTree>* base, std::string* error) {
  const auto& persistence = config_.persistence();
  if (persistence.path().empty()) return true;
  for (const std::string& stale : RemoveStaleTempFiles(persistence.path())) {
    spdlog::warn("snapshot: removed {}, left by a write that was killed", stale);
  }
  if (persistence.has_load_on_start() && !persistence.load_on_start()) return true;
  std::string message;
  switch (LoadSnapshotFile(persistence.path(), map_options_.resolution_m, base, &message)) {
    case LoadStatus::kLoaded:
      spdlog::info("snapshot: loaded {} ({} nodes)", persistence.path(), (*base)->size());
      return true;
    case LoadStatus::kMissing:
      spdlog::info("snapshot: {} does not exist yet; starting with an empty map",
                   persistence.path());
      return true;
    case LoadStatus::kCorrupt:
      spdlog::error("snapshot: corrupt, not loaded: {}; starting with an empty map", message);
      return true;
    case LoadStatus::kError:
      break;
  }
  *error = "snapshot: " + message;
  return false;
}

bool MapStack::Start(std::string* error) {
  if (!ConvertConfig(error)) return false;
  // Queries before the first render see an empty map at the configured resolution.
  hub_ = std::make_unique<SnapshotHub>(SnapshotHub::kDefaultMaxLoggedRegions,
                                       config_.map().resolution_m());
  state_.hub = hub_.get();
  std::unique_ptr<octomap::OcTree> base;
  if (!LoadLastSnapshot(&base, error)) return false;

  WorkerOptions worker_options;
  worker_options.map = map_options_;
  worker_options.thresholds = state_.thresholds;
  worker_options.render_interval = std::chrono::milliseconds(config_.map().render_interval_ms());
  worker_options.wait_for_renderer = config_.ingest().reliability() == "reliable";
  worker_options.histograms = histograms_;
  worker_ = std::make_unique<FusionWorker>(worker_options, state_.sensors, queues_.get(),
                                           hub_.get());
  const bool loaded = base != nullptr;
  if (!worker_->Start(std::move(base), error)) return false;
  state_.worker = worker_.get();

  const auto& persistence = config_.persistence();
  persister_ = std::make_unique<Persister>(
      persistence.path(), std::chrono::seconds(persistence.interval_s()), hub_.get());
  if (loaded) persister_->set_saved_version(hub_->Current()->version);
  if (on_persistence_health_) persister_->set_on_health(on_persistence_health_);
  persister_->Start();
  state_.persister = persister_.get();

  heavy_pool_ = std::make_unique<QueryPool>(config_.limits().max_heavy_queries(),
                                            static_cast<int>(config_.limits().heavy_query_nice()));
  state_.heavy_pool = heavy_pool_.get();
  return true;
}

void MapStack::BeginShutdown() {
  state_.shutting_down = true;
  if (hub_) hub_->Close();  // ends the update streams
}

void MapStack::StopQueries() {
  heavy_pool_.reset();  // its calls poll shutting_down
  state_.heavy_pool = nullptr;
}

bool MapStack::Finish() {
  if (finished_) return true;
  finished_ = true;
  if (worker_) worker_->Stop();  // drains the queues, renders, publishes
  if (!persister_) return true;
  persister_->Stop();
  if (!persister_->enabled()) return true;
  std::uint64_t version = 0, bytes = 0;
  std::string error;
  if (persister_->SaveNow(&version, &bytes, &error)) return true;
  spdlog::error("final snapshot not written: {}", error);
  return false;
}

}  // namespace fusion::service
