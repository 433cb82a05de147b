#include "fusion/service/server.h"

#include <atomic>

#include <grpcpp/ext/proto_server_reflection_plugin.h>
#include <grpcpp/health_check_service_interface.h>
#include <spdlog/spdlog.h>

#include "fusion/service/dds_domain.h"
#include "fusion/v1/map_service.grpc.pb.h"

namespace fusion::service {

class FusionServer::MapService final : public fusion::v1::FusionMap::CallbackService {
 public:
  MapService() : start_(std::chrono::steady_clock::now()) {}

  grpc::ServerUnaryReactor* GetStats(grpc::CallbackServerContext* context,
                                     const fusion::v1::GetStatsRequest* /*request*/,
                                     fusion::v1::Stats* reply) override {
    reply->set_uptime_s(
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count());
    auto* reactor = context->DefaultReactor();
    reactor->Finish(grpc::Status::OK);
    return reactor;
  }

 private:
  std::chrono::steady_clock::time_point start_;
};

FusionServer::FusionServer(fusion::v1::ServiceConfig config) : config_(std::move(config)) {}

FusionServer::~FusionServer() { Shutdown(); }

bool FusionServer::Start(std::string* error) {
  participant_ = CreateParticipant(config_.dds_domain(), error);
  if (participant_ < 0) return false;

  grpc::EnableDefaultHealthCheckService(true);
  grpc::reflection::InitProtoReflectionServerBuilderPlugin();
  map_service_ = std::make_unique<MapService>();
  grpc::ServerBuilder builder;
  builder.AddListeningPort(config_.listen_address(), grpc::InsecureServerCredentials(), &port_);
  builder.RegisterService(map_service_.get());
  server_ = builder.BuildAndStart();
  if (!server_ || port_ == 0) {
    *error = "cannot listen on '" + config_.listen_address() + "'";
    server_.reset();
    return false;
  }
  auto* health = server_->GetHealthCheckService();
  health->SetServingStatus(true);
  health->SetServingStatus(fusion::v1::FusionMap::service_full_name(), true);
  return true;
}

void FusionServer::Shutdown(std::chrono::milliseconds deadline) {
  if (server_) {
    server_->GetHealthCheckService()->SetServingStatus(false);
    server_->Shutdown(std::chrono::system_clock::now() + deadline);
    server_.reset();
  }
  if (participant_ > 0) {
    dds_delete(participant_);
    participant_ = 0;
  }
}

}  // namespace fusion::service
