#include "fusion/service/server.h"

#include <grpcpp/ext/proto_server_reflection_plugin.h>
#include <grpcpp/health_check_service_interface.h>
#include <spdlog/spdlog.h>

#include "fusion/service/conversions.h"
#include "fusion/dds/participant.h"
#include "fusion/service/dds_ingest.h"
#include "fusion/service/fusion_worker.h"
#include "fusion/service/ingest_queues.h"
#include "fusion/service/map_service.h"
#include "fusion/service/map_snapshot.h"
#include "fusion/service/persistence.h"
#include "fusion/service/persister.h"

namespace fusion::service {

struct FusionServer::Parts {
  ServiceState state;
  std::unique_ptr<IngestQueues> queues;
  std::unique_ptr<SnapshotHub> hub;
  std::unique_ptr<FusionWorker> worker;
  std::unique_ptr<Persister> persister;
  std::unique_ptr<DdsIngest> ingest;
  std::unique_ptr<QueryPool> heavy_pool;
  std::unique_ptr<MapService> service;
};

FusionServer::FusionServer(fusion::v1::ServiceConfig config) : config_(std::move(config)) {}

FusionServer::~FusionServer() { (void)Shutdown(); }

bool FusionServer::Start(std::string* error) {
  parts_ = std::make_unique<Parts>();
  Parts& p = *parts_;
  p.state.config = config_;
  std::vector<std::pair<std::string, std::size_t>> queue_specs;
  for (int i = 0; i < config_.sensors_size(); ++i) {
    std::string detail;
    auto setup = SensorSetupFromConfig(config_.sensors(i), &detail);
    if (!setup) {
      *error = "sensors[" + std::to_string(i) + "]." + detail;
      return false;
    }
    queue_specs.emplace_back(setup->id, setup->queue_depth);
    p.state.sensors.push_back(std::move(*setup));
  }
  std::string detail;
  const auto map_options = WorldMapOptionsFromConfig(config_.map(), &detail);
  if (!map_options) {
    *error = "map." + detail;
    return false;
  }
  p.state.thresholds = ThresholdsFromConfig(config_.map());
  p.queues = std::make_unique<IngestQueues>(
      queue_specs, std::size_t{config_.ingest().max_queued_mb()} << 20);
  p.state.queues = p.queues.get();
  // Queries before the first render see an empty map at the configured resolution.
  p.hub = std::make_unique<SnapshotHub>(SnapshotHub::kDefaultMaxLoggedRegions,
                                        config_.map().resolution_m());
  p.state.hub = p.hub.get();

  // The last snapshot, if any: loaded, or set aside when corrupt.
  const auto& persistence = config_.persistence();
  std::unique_ptr<octomap::OcTree> base;
  if (!persistence.path().empty()) {
    for (const std::string& stale : RemoveStaleTempFiles(persistence.path())) {
      spdlog::warn("snapshot: removed {}, left by a write that was killed", stale);
    }
  }
  if (!persistence.path().empty() &&
      (!persistence.has_load_on_start() || persistence.load_on_start())) {
    std::string message;
    switch (LoadSnapshotFile(persistence.path(), map_options->resolution_m, &base, &message)) {
      case LoadStatus::kLoaded:
        spdlog::info("snapshot: loaded {} ({} nodes)", persistence.path(), base->size());
        break;
      case LoadStatus::kMissing:
        spdlog::info("snapshot: {} does not exist yet; starting with an empty map",
                     persistence.path());
        break;
      case LoadStatus::kCorrupt:
        spdlog::error("snapshot: corrupt, not loaded: {}; starting with an empty map", message);
        break;
      case LoadStatus::kError:
        *error = "snapshot: " + message;
        return false;
    }
  }

  WorkerOptions worker_options;
  worker_options.map = *map_options;
  worker_options.thresholds = p.state.thresholds;
  worker_options.render_interval = std::chrono::milliseconds(config_.map().render_interval_ms());
  worker_options.wait_for_renderer = config_.ingest().reliability() == "reliable";
  p.worker =
      std::make_unique<FusionWorker>(worker_options, p.state.sensors, p.queues.get(), p.hub.get());
  const bool loaded = base != nullptr;
  if (!p.worker->Start(std::move(base), error)) return false;
  p.state.worker = p.worker.get();
  p.persister = std::make_unique<Persister>(
      persistence.path(), std::chrono::seconds(persistence.interval_s()), p.hub.get());
  if (loaded) p.persister->set_saved_version(p.hub->Current()->version);
  p.persister->set_on_health([this](bool ok) { SetHealth(kPersistenceHealth, ok); });
  p.persister->Start();
  p.state.persister = p.persister.get();

  participant_ = fusion::dds::CreateParticipant(config_.dds_domain(), error);
  if (participant_ < 0) return false;
  DdsIngestOptions ingest_options;
  ingest_options.topic = config_.dds_topic();
  ingest_options.reliable = config_.ingest().reliability() == "reliable";
  ingest_options.limits.max_points = config_.ingest().max_points();
  ingest_options.limits.quaternion_tolerance = config_.ingest().quaternion_tolerance();
  ingest_options.limits.max_abs_translation_m = config_.ingest().max_abs_translation_m();
  ingest_options.limits.map_resolution_m = config_.map().resolution_m();
  ingest_options.max_queued_bytes = std::size_t{config_.ingest().max_queued_mb()} << 20;
  p.ingest = std::make_unique<DdsIngest>(p.queues.get(), ingest_options);
  if (!p.ingest->Start(participant_, error)) return false;

  grpc::EnableDefaultHealthCheckService(true);
  grpc::reflection::InitProtoReflectionServerBuilderPlugin();
  p.heavy_pool = std::make_unique<QueryPool>(config_.limits().max_heavy_queries(),
                                             static_cast<int>(config_.limits().heavy_query_nice()));
  p.state.heavy_pool = p.heavy_pool.get();
  p.service = std::make_unique<MapService>(&p.state);
  grpc::ServerBuilder builder;
  builder.AddListeningPort(config_.listen_address(), grpc::InsecureServerCredentials(), &port_);
  builder.RegisterService(p.service.get());
  server_ = builder.BuildAndStart();
  if (!server_ || port_ == 0) {
    *error = "cannot listen on '" + config_.listen_address() + "'";
    server_.reset();
    return false;
  }
  {
    std::lock_guard<std::mutex> lock(health_mutex_);
    health_ = server_->GetHealthCheckService();
    health_->SetServingStatus(true);
    health_->SetServingStatus(fusion::v1::FusionMap::service_full_name(), true);
    if (p.persister->enabled()) {
      health_->SetServingStatus(kPersistenceHealth, !p.persister->failing());
    }
  }
  spdlog::info("{} sensor(s) configured; map resolution {} m, rule {}", p.state.sensors.size(),
               map_options->resolution_m, config_.map().fusion_rule());
  return true;
}

void FusionServer::SetHealth(const std::string& service, bool serving) {
  std::lock_guard<std::mutex> lock(health_mutex_);
  if (health_ != nullptr) health_->SetServingStatus(service, serving);
  if (!serving) spdlog::warn("health: {} NOT_SERVING", service);
}

bool FusionServer::Shutdown(std::chrono::milliseconds deadline) {
  if (stopped_ || !parts_) return true;
  stopped_ = true;
  Parts& p = *parts_;
  p.state.shutting_down = true;
  {
    std::lock_guard<std::mutex> lock(health_mutex_);
    if (health_ != nullptr) health_->SetServingStatus(false);
    health_ = nullptr;
  }
  p.hub->Close();  // ends the update streams
  if (server_) {
    server_->Shutdown(std::chrono::system_clock::now() + deadline);
    p.heavy_pool.reset();  // its calls poll shutting_down; none may finish after the server
    server_.reset();
  }
  if (p.ingest) p.ingest->Stop();
  if (p.worker) p.worker->Stop();  // drains the queues, renders, publishes
  bool saved = true;
  if (p.persister) {
    p.persister->Stop();
    if (p.persister->enabled()) {
      std::uint64_t version = 0, bytes = 0;
      std::string error;
      if (!p.persister->SaveNow(&version, &bytes, &error)) {
        spdlog::error("final snapshot not written: {}", error);
        saved = false;
      }
    }
  }
  if (participant_ > 0) {
    dds_delete(participant_);
    participant_ = 0;
  }
  return saved;
}

}  // namespace fusion::service
