// The FusionMap gRPC service: one small handler per RPC (validate and convert the request,
// read the current map snapshot or call the worker, convert the reply). No exception leaves a
// handler; every error carries the status code that fits.
#pragma once

#include <atomic>
#include <chrono>

#include "fusion/service/admission.h"
#include "fusion/service/conversions.h"
#include "fusion/service/fusion_worker.h"
#include "fusion/service/ingest_queues.h"
#include "fusion/service/map_snapshot.h"
#include "fusion/service/persister.h"
#include "fusion/v1/config.pb.h"
#include "fusion/v1/map_service.grpc.pb.h"

namespace fusion::service {

// What the handlers read; owned by FusionServer, outlives the gRPC server.
struct ServiceState {
  fusion::v1::ServiceConfig config;
  std::vector<SensorSetup> sensors;
  StateThresholds thresholds;
  IngestQueues* queues = nullptr;
  SnapshotHub* hub = nullptr;
  FusionWorker* worker = nullptr;
  Persister* persister = nullptr;
  std::chrono::steady_clock::time_point start = std::chrono::steady_clock::now();
  std::atomic<bool> shutting_down{false};
  std::atomic<std::uint32_t> update_streams{0};  // open StreamUpdates subscriptions
  std::atomic<std::uint32_t> heavy_queries{0};   // FindPlanes, QueryBox, GetSnapshot running
  IngestPressure pressure;
  QueryPool* heavy_pool = nullptr;  // runs FindPlanes, QueryBox, GetSnapshot's serialization
};

class MapService final : public fusion::v1::FusionMap::CallbackService {
 public:
  explicit MapService(ServiceState* state) : state_(state) {}

  grpc::ServerUnaryReactor* GetStats(grpc::CallbackServerContext* context,
                                     const fusion::v1::GetStatsRequest* request,
                                     fusion::v1::Stats* reply) override;
  grpc::ServerUnaryReactor* QueryPoints(grpc::CallbackServerContext* context,
                                        const fusion::v1::QueryPointsRequest* request,
                                        fusion::v1::QueryPointsResponse* reply) override;
  grpc::ServerUnaryReactor* QueryBox(grpc::CallbackServerContext* context,
                                     const fusion::v1::QueryBoxRequest* request,
                                     fusion::v1::QueryBoxResponse* reply) override;
  grpc::ServerUnaryReactor* CastRay(grpc::CallbackServerContext* context,
                                    const fusion::v1::CastRayRequest* request,
                                    fusion::v1::CastRayResponse* reply) override;
  grpc::ServerUnaryReactor* FindPlanes(grpc::CallbackServerContext* context,
                                       const fusion::v1::FindPlanesRequest* request,
                                       fusion::v1::FindPlanesResponse* reply) override;
  grpc::ServerWriteReactor<fusion::v1::SnapshotChunk>* GetSnapshot(
      grpc::CallbackServerContext* context, const fusion::v1::GetSnapshotRequest* request) override;
  grpc::ServerWriteReactor<fusion::v1::MapUpdate>* StreamUpdates(
      grpc::CallbackServerContext* context,
      const fusion::v1::StreamUpdatesRequest* request) override;
  grpc::ServerUnaryReactor* ListSensors(grpc::CallbackServerContext* context,
                                        const fusion::v1::ListSensorsRequest* request,
                                        fusion::v1::ListSensorsResponse* reply) override;
  grpc::ServerUnaryReactor* InspectBeam(grpc::CallbackServerContext* context,
                                        const fusion::v1::InspectBeamRequest* request,
                                        fusion::v1::InspectBeamResponse* reply) override;
  grpc::ServerUnaryReactor* ResetMap(grpc::CallbackServerContext* context,
                                     const fusion::v1::ResetMapRequest* request,
                                     fusion::v1::ResetMapResponse* reply) override;
  grpc::ServerUnaryReactor* ClearBox(grpc::CallbackServerContext* context,
                                     const fusion::v1::ClearBoxRequest* request,
                                     fusion::v1::ClearBoxResponse* reply) override;
  grpc::ServerUnaryReactor* SaveMap(grpc::CallbackServerContext* context,
                                    const fusion::v1::SaveMapRequest* request,
                                    fusion::v1::SaveMapResponse* reply) override;

 private:
  ServiceState* state_;
};

}  // namespace fusion::service
