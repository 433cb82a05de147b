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

Status MapStack::ConvertConfig() {
  state_.config = config_;
  std::vector<std::pair<std::string, std::size_t>> queue_specs;
  for (int i = 0; i < config_.sensors_size(); ++i) {
    auto setup = SensorSetupFromConfig(config_.sensors(i));
    if (!setup.ok()) return setup.status().WithContext("sensors[" + std::to_string(i) + "]");
    queue_specs.emplace_back(setup->id, setup->queue_depth);
    state_.sensors.push_back(std::move(*setup));
  }
  const auto map_options = WorldMapOptionsFromConfig(config_.map());
  if (!map_options.ok()) return map_options.status().WithContext("map");
  map_options_ = *map_options;
  state_.thresholds = ThresholdsFromConfig(config_.map());
  queues_ = std::make_unique<IngestQueues>(
      queue_specs, std::size_t{config_.ingest().max_queued_mb()} << 20);
  state_.queues = queues_.get();
  return Status::Ok();
}

// The last snapshot, if any: loaded into *base, or set aside when corrupt.
Status MapStack::LoadLastSnapshot(std::unique_ptr<octomap::OcTree>* base) {
  const auto& persistence = config_.persistence();
  if (persistence.path().empty()) return Status::Ok();
  for (const std::string& stale : RemoveStaleTempFiles(persistence.path())) {
    spdlog::warn("snapshot: removed {}, left by a write that was killed", stale);
  }
  if (persistence.has_load_on_start() && !persistence.load_on_start()) return Status::Ok();
  std::string message;
  switch (LoadSnapshotFile(persistence.path(), map_options_.resolution_m, base, &message)) {
    case LoadStatus::kLoaded:
      spdlog::info("snapshot: loaded {} ({} nodes)", persistence.path(), (*base)->size());
      return Status::Ok();
    case LoadStatus::kMissing:
      spdlog::info("snapshot: {} does not exist yet; starting with an empty map",
                   persistence.path());
      return Status::Ok();
    case LoadStatus::kCorrupt:
      spdlog::error("snapshot: corrupt, not loaded: {}; starting with an empty map", message);
      return Status::Ok();
    case LoadStatus::kError:
      break;
  }
  return Status::Error("snapshot: " + message);
}

Status MapStack::Start() {
  if (Status converted = ConvertConfig(); !converted.ok()) return converted;
  // Queries before the first render see an empty map at the configured resolution.
  hub_ = std::make_unique<SnapshotHub>(SnapshotHub::kDefaultMaxLoggedRegions,
                                       config_.map().resolution_m());
  state_.hub = hub_.get();
  std::unique_ptr<octomap::OcTree> base;
  if (Status loaded = LoadLastSnapshot(&base); !loaded.ok()) return loaded;

  WorkerOptions worker_options;
  worker_options.map = map_options_;
  worker_options.thresholds = state_.thresholds;
  worker_options.render_interval = std::chrono::milliseconds(config_.map().render_interval_ms());
  worker_options.wait_for_renderer = config_.ingest().reliability() == "reliable";
  worker_options.histograms = histograms_;
  worker_ = std::make_unique<FusionWorker>(worker_options, state_.sensors, queues_.get(),
                                           hub_.get());
  const bool loaded = base != nullptr;
  if (Status started = worker_->Start(std::move(base)); !started.ok()) return started;
  state_.worker = worker_.get();

  const auto& persistence = config_.persistence();
  persister_ = std::make_unique<Persister>(
      persistence.path(), std::chrono::seconds(persistence.interval_s()), hub_.get());
  if (loaded) persister_->set_saved_version(hub_->Current()->version);
  if (on_persistence_health_) persister_->set_on_health(on_persistence_health_);
  persister_->Start();
  state_.persister = persister_.get();

  heavy_pool_ = std::make_unique<QueryPool>(
      config_.limits().max_heavy_queries(), static_cast<int>(config_.limits().heavy_query_nice()),
      [this] { (void)heap_trimmer_.MaybeTrim(std::chrono::steady_clock::now()); });
  state_.heavy_pool = heavy_pool_.get();
  return Status::Ok();
}

void MapStack::BeginShutdown() {
  state_.shutting_down = true;
  if (hub_) hub_->Close();  // ends the update streams
}

void MapStack::StopQueries() {
  heavy_pool_.reset();  // its calls poll shutting_down
  state_.heavy_pool = nullptr;
}

Status MapStack::Finish() {
  if (finished_) return Status::Ok();
  finished_ = true;
  if (worker_) worker_->Stop();  // drains the queues, renders, publishes
  if (!persister_) return Status::Ok();
  persister_->Stop();
  if (!persister_->enabled()) return Status::Ok();
  std::uint64_t version = 0, bytes = 0;
  const Status saved = persister_->SaveNow(&version, &bytes);
  if (!saved.ok()) spdlog::error("final snapshot not written: {}", saved.message());
  return saved.WithContext("final snapshot");
}

}  // namespace fusion::service
