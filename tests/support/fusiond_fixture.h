// The fusiond test fixture: a real fusiond process on 127.0.0.1:0 in a private DDS domain,
// configured for the board scene (a quarter-resolution SR-3000, reliable ingest, persistence
// in a private directory), with helpers that publish simulated frames over DDS and query it.
#pragma once

#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "dds_publisher.h"
#include "fusion/core/sensor.h"
#include "fusion/sim/scene.h"
#include "fusion/sim/simulator.h"
#include "fusion/v1/map_service.grpc.pb.h"
#include "request_helpers.h"
#include "subprocess.h"

namespace fusion::testing {

using namespace std::chrono_literals;
namespace v1 = fusion::v1;
namespace fs = std::filesystem;

const std::string kFusiond = std::string(FUSION_BINARY_DIR) + "/service/fusiond";
constexpr int kCols = 44;  // SR-3000 field of view with a quarter of its beams: fast tests
constexpr int kRows = 36;

// A point on the paper's board (x = 1.75) and one in the free space in front of it.
const Eigen::Vector3d kOnBoard(1.75, 0.0, 0.2);
const Eigen::Vector3d kInFront(1.0, 0.0, 0.2);

class FusiondServiceTest : public ::testing::Test {
 protected:
  void SetUp() override {
    // A domain per test: a fusiond killed with SIGKILL stays a matched (dead) reader in its
    // domain until its DDS lease expires, and reliable writers would wait for its acks.
    static unsigned test_index = 0;
    domain_ = fusion::testing::PrivateDomainId(test_index++);
    dir_ = ::testing::TempDir() + "fusiond_service_" + std::to_string(getpid()) + "_" +
           ::testing::UnitTest::GetInstance()->current_test_info()->name();
    fs::remove_all(dir_);
    fs::create_directories(dir_);
    snapshot_ = dir_ + "/map.ot";
    config_ = dir_ + "/fusiond.pbtxt";
    std::ofstream(config_) << "listen_address: \"127.0.0.1:0\"\n"
                           << "dds_domain: " << domain_ << "\n"
                           << "log_level: \"warn\"\n"
                           << "sensors { id: \"sr\" preset: \"sr3000\" cols: " << kCols
                           << " rows: " << kRows << " }\n"
                           << "map { resolution_m: 0.05 render_interval_ms: 100 }\n"
                           << "ingest { reliability: \"reliable\" max_points: 100000 }\n"
                           << "limits { max_points_per_query: 1000 max_box_voxels: 2000000 "
                           << "max_voxels_per_page: 50000 }\n"
                           << "persistence { path: \"" << snapshot_ << "\" interval_s: 1 }\n";
  }

  // Starts fusiond and connects the stubs; with `stderr_path` its log is appended there.
  std::unique_ptr<Subprocess> Start(const std::string& stderr_path = "") {
    std::vector<std::string> argv{kFusiond, "--config", config_};
    if (!stderr_path.empty()) {
      argv = {"/bin/sh", "-c",
              "exec '" + kFusiond + "' --config '" + config_ + "' 2>>'" + stderr_path + "'"};
    }
    auto process = std::make_unique<Subprocess>(argv);
    EXPECT_TRUE(process->started());
    const auto port = process->WaitForOutput(R"(listening on 127\.0\.0\.1:(\d+))", 20s);
    EXPECT_TRUE(port) << "no port line in: " << process->output();
    if (!port) return nullptr;
    channel_ = grpc::CreateChannel("127.0.0.1:" + *port, grpc::InsecureChannelCredentials());
    stub_ = v1::FusionMap::NewStub(channel_);
    return process;
  }

  v1::PointOccupancy Occupancy(const Eigen::Vector3d& p, std::uint64_t* version = nullptr) {
    grpc::ClientContext context;
    context.set_deadline(In(5s));
    v1::QueryPointsRequest request;
    *request.add_points() = P(p);
    v1::QueryPointsResponse reply;
    const auto status = stub_->QueryPoints(&context, request, &reply);
    EXPECT_TRUE(status.ok()) << status.error_message();
    if (version) *version = reply.map_version();
    return reply.results_size() == 1 ? reply.results(0) : v1::PointOccupancy();
  }

  v1::Stats Stats() {
    grpc::ClientContext context;
    context.set_deadline(In(5s));
    v1::Stats stats;
    EXPECT_TRUE(stub_->GetStats(&context, v1::GetStatsRequest(), &stats).ok());
    return stats;
  }

  v1::SensorCounters SrCounters() {
    grpc::ClientContext context;
    context.set_deadline(In(5s));
    v1::ListSensorsResponse reply;
    EXPECT_TRUE(stub_->ListSensors(&context, v1::ListSensorsRequest(), &reply).ok());
    for (const auto& s : reply.sensors()) {
      if (s.id() == "sr") return s.counters();
    }
    ADD_FAILURE() << "sensor 'sr' not listed";
    return {};
  }

  // One simulated SR-3000 frame of the board scene from the origin.
  void PublishBoardFrame(TestPublisher& publisher, std::uint64_t seq) {
    auto spec = fusion::sim::WithTessellation(*fusion::SensorPreset("sr3000"), kCols, kRows);
    fusion::sim::RangeSimulator simulator(fusion::sim::PaperBoardScene(), spec);
    simulator.Reseed(seq);  // each frame its own noise
    const Eigen::Isometry3d pose = fusion::sim::ForwardLookingPose(Eigen::Vector3d::Zero());
    const auto frame = simulator.Capture(pose);
    TestCloud cloud;
    cloud.sequence_number = seq;
    cloud.SetPose(pose);
    cloud.width = frame.cols;
    cloud.height = frame.rows;
    cloud.xyz = frame.xyz;
    cloud.beyond_range = frame.beyond_range;
    EXPECT_TRUE(publisher.Publish(cloud));
  }

  // Publishes simulated frames of the board scene until the board is occupied and the space
  // in front of it free. Returns the map version that showed it.
  std::uint64_t MapTheBoard(TestPublisher& publisher) {
    const auto end = std::chrono::steady_clock::now() + 20s;
    for (std::uint64_t seq = 1; std::chrono::steady_clock::now() < end; ++seq) {
      PublishBoardFrame(publisher, seq);
      std::this_thread::sleep_for(100ms);
      std::uint64_t version = 0;
      // A few frames at least: one frame leaves p(B) of a beam diffuse (the prior still weighs).
      if (seq >= 5 && Occupancy(kOnBoard, &version).state() == v1::VOXEL_STATE_OCCUPIED &&
          Occupancy(kInFront).state() == v1::VOXEL_STATE_FREE) {
        return version;
      }
    }
    ADD_FAILURE() << "the board did not appear within 20 s";
    return 0;
  }

  unsigned domain_ = 0;
  std::string dir_, snapshot_, config_;
  std::shared_ptr<grpc::Channel> channel_;
  std::unique_ptr<v1::FusionMap::Stub> stub_;
};

}  // namespace fusion::testing
