// End to end with the Python example client: clients/python/path_check.py (run with
// /usr/bin/python3 and the stubs of target fusion_python_stubs) against a fusiond process
// fed by fusion-sim-sensor (SR-3000, the paper's board 1.75 m ahead of the sensor at the
// origin, looking along world +x).
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <memory>
#include <regex>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "../support/subprocess.h"
#include "fusion/v1/map_service.grpc.pb.h"

namespace {

using fusion::testing::Subprocess;
using namespace std::chrono_literals;
namespace v1 = fusion::v1;
namespace fs = std::filesystem;

const std::string kBuild = FUSION_BINARY_DIR;
const std::string kTools = kBuild + "/clients/";
const std::string kPython = "/usr/bin/python3";
// The repository root: FUSION_SHARED_DATA_DIR is "<repo>/../shared/data".
const std::string kRepo = [] {
  const std::string dir = FUSION_SHARED_DATA_DIR;
  return dir.substr(0, dir.size() - std::string("/../shared/data").size());
}();

// Runs a tool to completion; returns its exit code (-1: did not finish) and stdout.
int RunTool(std::vector<std::string> argv, std::string* out = nullptr,
            std::chrono::seconds timeout = 60s) {
  argv[0] = kTools + argv[0];
  Subprocess process(argv);
  if (!process.started()) return -1;
  process.WaitForOutput("(?!)", timeout);  // drains stdout until the child exits
  const int code = process.Wait(5000ms);
  if (out) *out = process.output();
  return code;
}

// A fusiond process with its own temporary folder and DDS domain, and gRPC stubs to it.
class E2eService : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = ::testing::TempDir() + "e2e_" + std::to_string(getpid()) + "_" +
           ::testing::UnitTest::GetInstance()->current_test_info()->name();
    fs::remove_all(dir_);
    fs::create_directories(dir_);
    domain_ = fusion::testing::PrivateDomainId();
  }
  void TearDown() override {
    if (!dir_.empty()) fs::remove_all(dir_);
  }

  // Starts fusiond with `config` (written to the temporary folder) on 127.0.0.1:0 in the
  // test's DDS domain, plus `extra` flags.
  void StartFusiond(const std::string& config, std::vector<std::string> extra = {}) {
    const std::string path = dir_ + "/fusiond.pbtxt";
    std::ofstream(path) << config;
    StartFusiondWithFile(path, std::move(extra));
  }
  void StartFusiondWithFile(const std::string& path, std::vector<std::string> extra = {}) {
    std::vector<std::string> argv = {kBuild + "/service/fusiond", "--config", path, "--listen",
                                     "127.0.0.1:0", "--dds-domain", std::to_string(domain_)};
    argv.insert(argv.end(), extra.begin(), extra.end());
    fusiond_ = std::make_unique<Subprocess>(argv);
    ASSERT_TRUE(fusiond_->started());
    const auto port = fusiond_->WaitForOutput(R"(fusiond listening on 127\.0\.0\.1:(\d+))", 20s);
    ASSERT_TRUE(port) << "no 'listening' line: " << fusiond_->output();
    address_ = "127.0.0.1:" + *port;
    stub_ = v1::FusionMap::NewStub(grpc::CreateChannel(address_, grpc::InsecureChannelCredentials()));
  }

  v1::SensorCounters Counters(const std::string& id) {
    grpc::ClientContext context;
    context.set_deadline(std::chrono::system_clock::now() + 5s);
    v1::ListSensorsResponse reply;
    const auto status = stub_->ListSensors(&context, v1::ListSensorsRequest(), &reply);
    EXPECT_TRUE(status.ok()) << status.error_message();
    for (const auto& s : reply.sensors()) {
      if (s.id() == id) return s.counters();
    }
    ADD_FAILURE() << "sensor " << id << " not listed";
    return {};
  }

  v1::Stats Stats() {
    grpc::ClientContext context;
    context.set_deadline(std::chrono::system_clock::now() + 5s);
    v1::Stats stats;
    EXPECT_TRUE(stub_->GetStats(&context, v1::GetStatsRequest(), &stats).ok());
    return stats;
  }

  // Waits until `frames` clouds of sensor `id` are integrated and rendered.
  bool WaitIntegrated(const std::string& id, std::uint64_t frames, std::chrono::seconds timeout,
                      std::chrono::milliseconds quiet = 500ms) {
    const auto end = std::chrono::steady_clock::now() + timeout;
    while (Counters(id).integrated() < frames) {
      if (std::chrono::steady_clock::now() > end) return false;
      std::this_thread::sleep_for(50ms);
    }
    // The worker renders pending changes every render_interval_ms (100 ms here): once no
    // render happened for `quiet`, the last cloud is in the published map.
    auto renders = Stats().renders();
    for (;;) {
      std::this_thread::sleep_for(quiet);
      const auto now = Stats().renders();
      if (now == renders || std::chrono::steady_clock::now() > end) break;
      renders = now;
    }
    return true;
  }

  std::string dir_;
  unsigned domain_ = 0;
  std::unique_ptr<Subprocess> fusiond_;
  std::unique_ptr<v1::FusionMap::Stub> stub_;
  std::string address_;
};

// Runs path_check.py; returns its exit code and stdout + stderr.
int PathCheck(const std::string& server, const std::string& from, const std::string& to,
              std::string* out) {
  const std::string log = ::testing::TempDir() + "path_check_" + std::to_string(getpid()) + ".log";
  Subprocess process(
      {"/bin/sh", "-c",
       "exec " + kPython + " " + kRepo + "/clients/python/path_check.py --server " + server +
           " --from " + from + " --to " + to + " --timeout 3 2>&1"},
      {"PYTHONPATH=" + kBuild + "/clients/python"});
  process.WaitForOutput("(?!)", 30s);
  const int code = process.Wait(5000ms);
  *out = process.output();
  return code;
}

class E2ePythonClientTest : public E2eService {
 protected:
  void SetUp() override {
    if (access(kPython.c_str(), X_OK) != 0) GTEST_SKIP() << kPython << " is not installed";
    if (std::system((kPython + " -c 'import grpc, google.protobuf' 2>/dev/null").c_str()) != 0) {
      GTEST_SKIP() << kPython << " lacks grpc (apt-get install python3-grpcio python3-protobuf)";
    }
    if (!fs::exists(kBuild + "/clients/python/fusion/v1/map_service_pb2_grpc.py")) {
      GTEST_SKIP() << "no Python stubs in " << kBuild
                   << "/clients/python (target fusion_python_stubs needs grpc_python_plugin)";
    }
    E2eService::SetUp();
  }
};

TEST_F(E2ePythonClientTest, PathCheckFindsTheBoard) {
  ASSERT_NO_FATAL_FAILURE(
      StartFusiond("log_level: \"warn\"\n"
                   "sensors { id: \"sr3000\" preset: \"sr3000\" }\n"
                   "map { resolution_m: 0.05 render_interval_ms: 100 }\n"
                   "ingest { reliability: \"reliable\" }\n"));
  std::string out;
  ASSERT_EQ(RunTool({"fusion-sim-sensor", "--preset", "sr3000", "--frames", "10", "--rate", "20",
                     "--reliable", "--wait-readers", "1", "--domain", std::to_string(domain_)},
                    &out),
            0)
      << out;
  EXPECT_NE(out.find("published 10 frames"), std::string::npos) << out;
  ASSERT_TRUE(WaitIntegrated("sr3000", 10, 30s))
      << "integrated " << Counters("sr3000").integrated() << " of 10";

  // In front of the board: clear.
  EXPECT_EQ(PathCheck(address_, "0.5,0,0", "1.2,0,0", &out), 0) << out;
  EXPECT_EQ(out.rfind("clear (", 0), 0u) << out;
  std::smatch m;
  ASSERT_TRUE(std::regex_search(out, m, std::regex(R"((\d+) occupied, (\d+) free)"))) << out;
  EXPECT_EQ(m[1], "0") << out;
  EXPECT_GT(std::stoi(m[2]), 20) << "most samples lie in observed free space: " << out;

  // Through the board (x = 1.75): blocked about 1.25 m from the start.
  EXPECT_EQ(PathCheck(address_, "0.5,0,0", "2.5,0,0", &out), 1) << out;
  ASSERT_TRUE(std::regex_search(
      out, m, std::regex(R"(blocked at ([0-9.]+) m: ([-0-9.]+),([-0-9.]+),([-0-9.]+))")))
      << out;
  EXPECT_NEAR(std::stod(m[1]), 1.25, 0.1) << out;
  EXPECT_NEAR(std::stod(m[2]), 1.75, 0.1) << out;

  // Nobody listening: exit 2 with a message.
  EXPECT_NO_FATAL_FAILURE(fusiond_->Stop(SIGTERM, 10000ms));
  EXPECT_EQ(PathCheck(address_, "0.5,0,0", "1.2,0,0", &out), 2) << out;
  EXPECT_NE(out.find("cannot query fusiond"), std::string::npos) << out;
}

}  // namespace
