// fusiond's gRPC front: the FusionMap service, the standard health service and reflection.
#pragma once

#include <chrono>
#include <memory>
#include <string>

#include <grpcpp/grpcpp.h>

#include "fusion/v1/config.pb.h"

namespace fusion::service {

class FusionServer {
 public:
  explicit FusionServer(fusion::v1::ServiceConfig config);
  ~FusionServer();
  FusionServer(const FusionServer&) = delete;
  FusionServer& operator=(const FusionServer&) = delete;

  // Joins DDS and starts listening. Returns false with *error set on failure.
  bool Start(std::string* error);
  // Port actually bound (useful with port 0).
  [[nodiscard]] int port() const { return port_; }
  // Stops accepting calls, lets running ones finish within the deadline, leaves DDS.
  void Shutdown(std::chrono::milliseconds deadline = std::chrono::milliseconds(2000));

 private:
  class MapService;
  fusion::v1::ServiceConfig config_;
  std::unique_ptr<MapService> map_service_;
  std::unique_ptr<grpc::Server> server_;
  int port_ = 0;
  int participant_ = 0;
};

}  // namespace fusion::service
