#include "fusion/service/server.h"

#include <grpcpp/ext/proto_server_reflection_plugin.h>
#include <grpcpp/health_check_service_interface.h>
#include <spdlog/spdlog.h>

#include "fusion/service/conversions.h"
#include "fusion/dds/participant.h"
#include "fusion/service/dds_ingest.h"
#include "fusion/service/map_service.h"
#include "fusion/service/map_stack.h"
#include "fusion/service/metrics.h"
#include "fusion/service/ros2_ingest.h"
#include "fusion/service/ros2_output.h"
#include "fusion/service/security.h"

namespace fusion::service {

struct FusionServer::Parts {
  std::unique_ptr<Metrics> metrics;  // first: the server's interceptors use it to the end
  std::unique_ptr<MapStack> stack;
  std::unique_ptr<DdsIngest> ingest;
  std::unique_ptr<Ros2Ingest> ros2_ingest;  // sensors with a ros2_topic (none: no readers)
  std::unique_ptr<Ros2Output> ros2_output;  // the map as octomap_msgs (off: no writers)
  std::unique_ptr<MapService> service;
};

FusionServer::FusionServer(fusion::v1::ServiceConfig config) : config_(std::move(config)) {}

FusionServer::~FusionServer() { (void)Shutdown(); }

Status FusionServer::Start() {
  parts_ = std::make_unique<Parts>();
  Parts& p = *parts_;
  p.stack = std::make_unique<MapStack>(
      config_, [this](bool ok) { SetHealth(kPersistenceHealth, ok); });
  const std::string& metrics_address = config_.metrics().listen_address();
  if (!metrics_address.empty()) {
    // Bound first: a taken port is refused before anything else starts.
    p.metrics = std::make_unique<Metrics>();
    if (Status listening = p.metrics->Listen(metrics_address); !listening.ok()) {
      return listening.WithContext("metrics.listen_address");
    }
    p.stack->set_worker_histograms(p.metrics->worker());
  }
  if (Status started = p.stack->Start(); !started.ok()) return started;
  if (p.metrics) p.metrics->Observe(p.stack->state());

  std::string dds_error;
  participant_ = fusion::dds::CreateParticipant(config_.dds_domain(), &dds_error);
  if (participant_ < 0) return Status::Error(dds_error);
  DdsIngestOptions ingest_options;
  ingest_options.topic = config_.dds_topic();
  ingest_options.reliable = config_.ingest().reliability() == "reliable";
  ingest_options.limits.max_points = config_.ingest().max_points();
  ingest_options.limits.quaternion_tolerance = config_.ingest().quaternion_tolerance();
  ingest_options.limits.max_abs_translation_m = config_.ingest().max_abs_translation_m();
  ingest_options.limits.map_resolution_m = config_.map().resolution_m();
  ingest_options.max_queued_bytes = std::size_t{config_.ingest().max_queued_mb()} << 20;
  p.ingest = std::make_unique<DdsIngest>(p.stack->queues(), ingest_options);
  if (Status started = p.ingest->Start(participant_); !started.ok()) return started;
  auto ros2_options = Ros2IngestOptionsFromConfig(config_);
  if (!ros2_options.ok()) return ros2_options.status();
  FusionWorker* worker = p.stack->state()->worker;
  p.ros2_ingest =
      std::make_unique<Ros2Ingest>(p.stack->queues(), std::move(*ros2_options),
                                   [worker](const std::string& id, const SensorSpec& spec) {
                                     return worker->DefineSensor(id, spec);
                                   });
  if (Status started = p.ros2_ingest->Start(participant_); !started.ok()) return started;
  auto output_options = Ros2OutputOptionsFromConfig(config_);
  if (!output_options.ok()) return output_options.status();
  const bool output_enabled = output_options->enabled();
  p.ros2_output = std::make_unique<Ros2Output>(p.stack->state()->hub, std::move(*output_options));
  if (Status started = p.ros2_output->Start(participant_); !started.ok()) return started;
  if (p.metrics && output_enabled) p.metrics->ObserveRos2Output(p.ros2_output.get());

  const auto credentials = ServerCredentialsFor(config_.security());
  if (!credentials.ok()) return credentials.status().WithContext("security");
  grpc::EnableDefaultHealthCheckService(true);
  // The plugin is registered for every server built after it: once, only when wanted.
  if (ReflectionEnabled(config_.security())) grpc::reflection::InitProtoReflectionServerBuilderPlugin();
  p.service = std::make_unique<MapService>(p.stack->state());
  grpc::ServerBuilder builder;
  builder.AddListeningPort(config_.listen_address(), *credentials, &port_);
  builder.RegisterService(p.service.get());
  if (p.metrics) {
    std::vector<std::unique_ptr<grpc::experimental::ServerInterceptorFactoryInterface>> creators;
    creators.push_back(p.metrics->RpcInterceptorFactory());
    builder.experimental().SetInterceptorCreators(std::move(creators));
  }
  server_ = builder.BuildAndStart();
  if (!server_ || port_ == 0) {
    server_.reset();
    return Status::Error("cannot listen on '" + config_.listen_address() + "'");
  }
  {
    std::lock_guard<std::mutex> lock(health_mutex_);
    health_ = server_->GetHealthCheckService();
    health_->SetServingStatus(true);
    health_->SetServingStatus(fusion::v1::FusionMap::service_full_name(), true);
    const Persister* persister = p.stack->state()->persister;
    if (persister->enabled()) {
      health_->SetServingStatus(kPersistenceHealth, !persister->failing());
    }
  }
  spdlog::info("{} sensor(s) configured; map resolution {} m, rule {}",
               p.stack->state()->sensors.size(), p.stack->map_options().resolution_m,
               config_.map().fusion_rule());
  const auto& security = config_.security();
  spdlog::info("gRPC: {}{}, {}, reflection {}",
               security.tls_cert_file().empty() ? "plaintext" : "TLS",
               security.tls_client_ca_file().empty() ? "" : " with client certificates",
               security.tokens_file().empty() ? "no tokens" : "bearer tokens",
               ReflectionEnabled(security) ? "on" : "off");
  return Status::Ok();
}

int FusionServer::metrics_port() const {
  return parts_ && parts_->metrics ? parts_->metrics->port() : 0;
}

void FusionServer::SetHealth(const std::string& service, bool serving) {
  std::lock_guard<std::mutex> lock(health_mutex_);
  if (health_ != nullptr) health_->SetServingStatus(service, serving);
  if (!serving) spdlog::warn("health: {} NOT_SERVING", service);
}

Status FusionServer::Shutdown(std::chrono::milliseconds deadline) {
  if (stopped_ || !parts_) return Status::Ok();
  stopped_ = true;
  Parts& p = *parts_;
  {
    std::lock_guard<std::mutex> lock(health_mutex_);
    if (health_ != nullptr) health_->SetServingStatus(false);
    health_ = nullptr;
  }
  if (p.stack) p.stack->BeginShutdown();
  if (server_) {
    server_->Shutdown(std::chrono::system_clock::now() + deadline);
    if (p.stack) p.stack->StopQueries();  // no heavy call may finish after the server
    server_.reset();
  }
  if (p.ingest) p.ingest->Stop();
  if (p.ros2_ingest) p.ros2_ingest->Stop();
  if (p.ros2_output) p.ros2_output->Stop();
  const Status saved = p.stack ? p.stack->Finish() : Status::Ok();
  if (p.metrics) p.metrics->Stop();  // before the state its scrapes read goes
  if (participant_ > 0) {
    dds_delete(participant_);
    participant_ = 0;
  }
  return saved;
}

}  // namespace fusion::service
