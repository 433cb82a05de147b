// End-to-end test support: the project's tools run as processes, recordings read back, and a
// fixture that starts fusiond on 127.0.0.1:0 in a private DDS domain with gRPC stubs to it.
#pragma once

#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <Eigen/Geometry>
#include <chrono>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "fusion/v1/map_service.grpc.pb.h"
#include "fusion/v1/recording.pb.h"
#include "subprocess.h"

namespace fusion::testing {

inline const std::string kBuildDir = FUSION_BINARY_DIR;
inline const std::string kToolsDir = kBuildDir + "/clients/";
// The repository root: FUSION_SHARED_DATA_DIR is "<repo>/../shared/data".
inline const std::string kRepoDir = [] {
  const std::string dir = FUSION_SHARED_DATA_DIR;
  return dir.substr(0, dir.size() - std::string("/../shared/data").size());
}();

// Runs one of the client tools (argv[0] names it) to completion; returns its exit code
// (-1: did not finish) and stdout.
inline int RunTool(std::vector<std::string> argv, std::string* out = nullptr,
                   std::chrono::seconds timeout = std::chrono::seconds(60)) {
  argv[0] = kToolsDir + argv[0];
  Subprocess process(argv);
  if (!process.started()) return -1;
  process.WaitForOutput("(?!)", timeout);  // drains stdout until the child exits
  const int code = process.Wait(std::chrono::milliseconds(5000));
  if (out) *out = process.output();
  return code;
}

// The clouds of a .frec file (docs/recording-format.md), read frame by frame.
inline std::vector<fusion::v1::RecordedCloud> ReadRecording(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::vector<fusion::v1::RecordedCloud> clouds;
  for (;;) {
    std::uint32_t head[2];
    if (!in.read(reinterpret_cast<char*>(head), sizeof head)) break;
    std::string payload(head[0], '\0');
    if (!in.read(payload.data(), head[0])) break;
    fusion::v1::RecordingFrame frame;
    if (!frame.ParseFromString(payload)) break;
    if (frame.has_cloud()) clouds.push_back(frame.cloud());
    if (frame.has_index()) break;
  }
  return clouds;
}

inline Eigen::Isometry3d Pose(const fusion::v1::RecordedPose& p) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = Eigen::Quaterniond(p.qw(), p.qx(), p.qy(), p.qz()).normalized().toRotationMatrix();
  T.translation() = Eigen::Vector3d(p.tx(), p.ty(), p.tz());
  return T;
}

// The finite points of a recorded cloud in the world frame.
inline std::vector<Eigen::Vector3d> WorldPoints(const fusion::v1::RecordedCloud& cloud) {
  std::vector<float> xyz(cloud.xyz_f32le().size() / sizeof(float));
  std::memcpy(xyz.data(), cloud.xyz_f32le().data(), xyz.size() * sizeof(float));
  const Eigen::Isometry3d T = Pose(cloud.t_world_sensor());
  std::vector<Eigen::Vector3d> points;
  for (std::size_t i = 0; i + 2 < xyz.size(); i += 3) {
    const Eigen::Vector3d p(xyz[i], xyz[i + 1], xyz[i + 2]);
    if (p.allFinite()) points.push_back(T * p);
  }
  return points;
}

// A fusiond process with its own temporary folder and DDS domain, and gRPC stubs to it.
class E2eService : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = ::testing::TempDir() + "e2e_" + std::to_string(getpid()) + "_" +
           ::testing::UnitTest::GetInstance()->current_test_info()->name();
    std::filesystem::remove_all(dir_);
    std::filesystem::create_directories(dir_);
    domain_ = PrivateDomainId();
  }
  void TearDown() override {
    if (!dir_.empty()) std::filesystem::remove_all(dir_);
  }

  // Starts fusiond with `config` (written to the temporary folder) on 127.0.0.1:0 in the
  // test's DDS domain, plus `extra` flags.
  void StartFusiond(const std::string& config, std::vector<std::string> extra = {}) {
    const std::string path = dir_ + "/fusiond.pbtxt";
    std::ofstream(path) << config;
    StartFusiondWithFile(path, std::move(extra));
  }
  void StartFusiondWithFile(const std::string& path, std::vector<std::string> extra = {}) {
    std::vector<std::string> argv = {
        kBuildDir + "/service/fusiond", "--config", path, "--listen", "127.0.0.1:0", "--dds-domain",
        std::to_string(domain_)};
    argv.insert(argv.end(), extra.begin(), extra.end());
    fusiond_ = std::make_unique<Subprocess>(argv);
    ASSERT_TRUE(fusiond_->started());
    const auto port = fusiond_->WaitForOutput(R"(fusiond listening on 127\.0\.0\.1:(\d+))",
                                              std::chrono::seconds(20));
    ASSERT_TRUE(port) << "no 'listening' line: " << fusiond_->output();
    address_ = "127.0.0.1:" + *port;
    stub_ = fusion::v1::FusionMap::NewStub(
        grpc::CreateChannel(address_, grpc::InsecureChannelCredentials()));
  }

  static void SetDeadline(grpc::ClientContext* context, std::chrono::seconds timeout) {
    context->set_deadline(std::chrono::system_clock::now() + timeout);
  }

  fusion::v1::SensorCounters Counters(const std::string& id) {
    grpc::ClientContext context;
    SetDeadline(&context, std::chrono::seconds(5));
    fusion::v1::ListSensorsResponse reply;
    const auto status = stub_->ListSensors(&context, fusion::v1::ListSensorsRequest(), &reply);
    EXPECT_TRUE(status.ok()) << status.error_message();
    for (const auto& s : reply.sensors()) {
      if (s.id() == id) return s.counters();
    }
    ADD_FAILURE() << "sensor " << id << " not listed";
    return {};
  }

  fusion::v1::Stats Stats() {
    grpc::ClientContext context;
    SetDeadline(&context, std::chrono::seconds(5));
    fusion::v1::Stats stats;
    EXPECT_TRUE(stub_->GetStats(&context, fusion::v1::GetStatsRequest(), &stats).ok());
    return stats;
  }

  // Waits until the map that queries see holds `frames` integrated clouds (of all sensors).
  bool WaitInMap(std::uint64_t frames, std::chrono::seconds timeout) {
    const auto end = std::chrono::steady_clock::now() + timeout;
    while (Stats().clouds_in_map() < frames) {
      if (std::chrono::steady_clock::now() > end) return false;
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    return true;
  }

  // The occupancy of `points` (world frame), one result per point.
  std::vector<fusion::v1::PointOccupancy> Query(const std::vector<Eigen::Vector3d>& points) {
    fusion::v1::QueryPointsRequest request;
    for (const auto& p : points) {
      auto* q = request.add_points();
      q->set_x(p.x());
      q->set_y(p.y());
      q->set_z(p.z());
    }
    grpc::ClientContext context;
    SetDeadline(&context, std::chrono::seconds(10));
    fusion::v1::QueryPointsResponse reply;
    const auto status = stub_->QueryPoints(&context, request, &reply);
    EXPECT_TRUE(status.ok()) << status.error_message();
    return {reply.results().begin(), reply.results().end()};
  }

  std::string dir_;
  unsigned domain_ = 0;
  std::unique_ptr<Subprocess> fusiond_;
  std::unique_ptr<fusion::v1::FusionMap::Stub> stub_;
  std::string address_;
};

}  // namespace fusion::testing
