// Handler tests: a MapService over gRPC's in-process channel (no port, no process, no DDS)
// against a MapStack, with clouds pushed straight into its ingest queues. Requests are written
// as text-format protos. The scene: one sensor "cam" (a coarse SR-3000) at the origin looking
// along +z at a wall, the plane z = kWallZ, every beam reading it.
#pragma once

#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include <chrono>
#include <memory>
#include <string>
#include <thread>

#include "fusion/core/beam_tessellation.h"
#include "fusion/service/config.h"
#include "fusion/service/map_service.h"
#include "fusion/service/map_stack.h"
#include "fusion/v1/map_service.grpc.pb.h"
#include "text_proto.h"

namespace fusion::service::testing {

using namespace std::chrono_literals;
namespace v1 = fusion::v1;

constexpr double kWallZ = 2.025;  // the middle of a voxel at 5 cm
constexpr double kResolutionM = 0.05;

inline std::string PointText(const Eigen::Vector3d& p) {
  return "x: " + std::to_string(p.x()) + " y: " + std::to_string(p.y()) +
         " z: " + std::to_string(p.z());
}

class HandlerTest : public ::testing::Test {
 protected:
  // `extra` (text format) is merged over the fixture's configuration: limits, persistence...
  void StartService(const std::string& extra = "") {
    config_ = DefaultConfig();
    config_.MergeFrom(Text<v1::ServiceConfig>(
        "log_level: \"warn\"\n"
        "sensors { id: \"cam\" preset: \"sr3000\" cols: 22 rows: 18 }\n"
        "map { resolution_m: 0.05 render_interval_ms: 10 }\n"
        "limits { max_points_per_query: 100 max_voxels_per_page: 1000 }\n"));
    config_.MergeFrom(Text<v1::ServiceConfig>(extra));
    const fusion::Status valid = ValidateConfig(config_);
    ASSERT_TRUE(valid.ok()) << valid.message();
    stack_ = std::make_unique<MapStack>(config_, nullptr);
    const fusion::Status started = stack_->Start();
    ASSERT_TRUE(started.ok()) << started.message();
    service_ = std::make_unique<MapService>(stack_->state());
    grpc::ServerBuilder builder;
    builder.RegisterService(service_.get());
    server_ = builder.BuildAndStart();
    ASSERT_NE(server_, nullptr);
    stub_ = v1::FusionMap::NewStub(server_->InProcessChannel(grpc::ChannelArguments()));
  }

  void SetUp() override { StartService(); }

  void TearDown() override {
    if (!stack_) return;
    stack_->BeginShutdown();
    if (server_) server_->Shutdown(std::chrono::system_clock::now() + 2s);
    stack_->StopQueries();
    server_.reset();
    EXPECT_TRUE(stack_->Finish().ok());
  }

  // The wall seen `frames` times from the origin; returns once all of them are in the map
  // (in_map counts the clouds since the last ResetMap).
  void SeeWall(int frames) {
    const std::uint64_t before = stack_->state()->worker->in_map();
    const BeamTessellation tessellation(stack_->state()->sensors.at(0).spec);
    for (int k = 0; k < frames; ++k) {
      Cloud cloud;
      cloud.sensor_id = "cam";
      cloud.sequence_number = ++sequence_;
      cloud.width = static_cast<std::uint32_t>(tessellation.cols());
      cloud.height = static_cast<std::uint32_t>(tessellation.rows());
      for (std::size_t b = 0; b < tessellation.beam_count(); ++b) {
        const Eigen::Vector3d direction = tessellation.Direction(b);
        const Eigen::Vector3d p = direction * (kWallZ / direction.z());
        cloud.xyz.insert(cloud.xyz.end(), {static_cast<float>(p.x()), static_cast<float>(p.y()),
                                           static_cast<float>(p.z())});
      }
      ASSERT_TRUE(stack_->queues()->Push(std::move(cloud), &never_));  // waits, drops nothing
    }
    const auto end = std::chrono::steady_clock::now() + 20s;
    const std::uint64_t expected = before + static_cast<std::uint64_t>(frames);
    while (stack_->state()->worker->in_map() < expected && std::chrono::steady_clock::now() < end) {
      std::this_thread::sleep_for(2ms);
    }
    ASSERT_EQ(stack_->state()->worker->in_map(), expected);
  }

  // A unary call with a deadline; the status, the reply in *reply.
  template <typename Request, typename Reply, typename Call>
  grpc::Status Unary(Call call, const Request& request, Reply* reply,
                     std::chrono::milliseconds deadline = 10s) {
    grpc::ClientContext context;
    context.set_deadline(std::chrono::system_clock::now() + deadline);
    return (stub_.get()->*call)(&context, request, reply);
  }

  grpc::Status QueryPoints(const std::string& text, v1::QueryPointsResponse* reply) {
    return Unary(&v1::FusionMap::Stub::QueryPoints, Text<v1::QueryPointsRequest>(text), reply);
  }
  grpc::Status QueryBox(const std::string& text, v1::QueryBoxResponse* reply) {
    return Unary(&v1::FusionMap::Stub::QueryBox, Text<v1::QueryBoxRequest>(text), reply);
  }
  grpc::Status CastRay(const std::string& text, v1::CastRayResponse* reply) {
    return Unary(&v1::FusionMap::Stub::CastRay, Text<v1::CastRayRequest>(text), reply);
  }
  grpc::Status FindPlanes(const std::string& text, v1::FindPlanesResponse* reply) {
    return Unary(&v1::FusionMap::Stub::FindPlanes, Text<v1::FindPlanesRequest>(text), reply, 60s);
  }
  grpc::Status InspectBeam(const std::string& text, v1::InspectBeamResponse* reply) {
    return Unary(&v1::FusionMap::Stub::InspectBeam, Text<v1::InspectBeamRequest>(text), reply);
  }
  v1::Stats Stats() {
    v1::Stats stats;
    EXPECT_TRUE(Unary(&v1::FusionMap::Stub::GetStats, v1::GetStatsRequest(), &stats).ok());
    return stats;
  }

  // The state QueryPoints gives one point.
  v1::VoxelState StateAt(const Eigen::Vector3d& p) {
    v1::QueryPointsResponse reply;
    const auto status = QueryPoints("points { " + PointText(p) + " }", &reply);
    EXPECT_TRUE(status.ok()) << status.error_message();
    return reply.results_size() == 1 ? reply.results(0).state() : v1::VOXEL_STATE_UNKNOWN;
  }

  v1::ServiceConfig config_;
  std::unique_ptr<MapStack> stack_;
  std::unique_ptr<MapService> service_;
  std::unique_ptr<grpc::Server> server_;
  std::unique_ptr<v1::FusionMap::Stub> stub_;
  std::uint64_t sequence_ = 0;
  const std::atomic<bool> never_{false};
};

// On the wall, in front of it (seen free), behind the sensor (never seen).
inline const Eigen::Vector3d kOnWall(0.0, 0.0, kWallZ);
inline const Eigen::Vector3d kInFront(0.0, 0.0, 1.0);
inline const Eigen::Vector3d kBehind(0.0, 0.0, -1.0);

}  // namespace fusion::service::testing
