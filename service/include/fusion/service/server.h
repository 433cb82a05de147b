// fusiond as a whole: configuration -> DDS ingest -> bounded queues -> fusion worker ->
// published snapshots -> gRPC (FusionMap, health, reflection), plus persistence.
#pragma once

#include <grpcpp/grpcpp.h>

#include <chrono>
#include <memory>
#include <mutex>
#include <string>

#include "fusion/core/status.h"
#include "fusion/v1/config.pb.h"

namespace fusion::service {

class FusionServer {
 public:
  // The configuration must have passed ValidateConfig.
  explicit FusionServer(fusion::v1::ServiceConfig config);
  ~FusionServer();
  FusionServer(const FusionServer&) = delete;
  FusionServer& operator=(const FusionServer&) = delete;

  // Loads the last snapshot, starts the worker, joins DDS and starts listening (a corrupt
  // snapshot is set aside and logged, not an error).
  [[nodiscard]] Status Start();
  // Port actually bound (useful with port 0).
  [[nodiscard]] int port() const { return port_; }
  // Port of the metrics endpoint (0: metrics off).
  [[nodiscard]] int metrics_port() const;
  // Stops serving (streams end, running calls get the deadline), leaves DDS, integrates what
  // is queued, writes the final snapshot: an error if that snapshot could not be written.
  [[nodiscard]] Status Shutdown(std::chrono::milliseconds deadline = std::chrono::milliseconds(2000));

  // The health service's entry for snapshot writes (SERVING unless they fail).
  static constexpr const char* kPersistenceHealth = "fusion.v1.Persistence";

 private:
  struct Parts;
  fusion::v1::ServiceConfig config_;
  std::unique_ptr<Parts> parts_;
  std::unique_ptr<grpc::Server> server_;
  int port_ = 0;
  int participant_ = 0;
  bool stopped_ = false;
  // The persister's thread reports to the health service while the server lives.
  std::mutex health_mutex_;
  grpc::HealthCheckServiceInterface* health_ = nullptr;
  void SetHealth(const std::string& service, bool serving);
};

}  // namespace fusion::service
