// The compose deployment (docker/compose.yaml) run natively: fusiond with the deployment's own
// configuration (docker/fusiond.pbtxt; --listen, --dds-domain and --snapshot override the
// container's address, domain and volume), the two simulated sensors as separate processes
// (as the sensor-sr3000 and sensor-stoc services run them) and fusionctl as the client.
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
#include <map>
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

// Runs fusionctl against `server`; returns its exit code and stdout.
int Fusionctl(const std::string& server, std::vector<std::string> args, std::string* out) {
  std::vector<std::string> argv = {"fusionctl", "--server", server, "--timeout", "5"};
  argv.insert(argv.end(), args.begin(), args.end());
  return RunTool(argv, out, 30s);
}

// `fusionctl sensors` rows: sensor -> integrated clouds.
std::map<std::string, long> IntegratedBySensor(const std::string& table) {
  std::map<std::string, long> integrated;
  std::istringstream in(table);
  std::string line;
  std::getline(in, line);  // header
  while (std::getline(in, line)) {
    std::istringstream row(line);
    std::string id, preset;
    long beams = 0, memory = 0, received = 0, count = 0;
    if (row >> id >> preset >> beams >> memory >> received >> count) integrated[id] = count;
  }
  return integrated;
}

struct Plane {
  double d, nx, ny, nz;
  long support;
};

// `fusionctl planes` rows: phi theta d (nx, ny, nz) support rms [extent].
std::vector<Plane> ParsePlanes(const std::string& table) {
  std::vector<Plane> planes;
  const std::regex row(
      R"(^\s*[-0-9.]+\s+[-0-9.]+\s+([-0-9.]+)\s+\(\s*([-0-9.]+),\s*([-0-9.]+),\s*([-0-9.]+)\)\s+(\d+))");
  std::istringstream in(table);
  for (std::string line; std::getline(in, line);) {
    std::smatch m;
    if (std::regex_search(line, m, row)) {
      planes.push_back({std::stod(m[1]), std::stod(m[2]), std::stod(m[3]), std::stod(m[4]),
                        std::stol(m[5])});
    }
  }
  return planes;
}

class E2eComposeTopologyTest : public E2eService {};

TEST_F(E2eComposeTopologyTest, SensorsFusiondAndClientMapTheBoard) {
  const std::string config = kRepo + "/docker/fusiond.pbtxt";
  ASSERT_TRUE(fs::exists(config)) << config << " (the compose deployment's configuration)";
  // The container's address, domain and volume would not do here: the flags override them.
  ASSERT_NO_FATAL_FAILURE(StartFusiondWithFile(config, {"--snapshot", dir_ + "/map.ot"}));

  // The client's health check, as compose's healthcheck runs it.
  std::string out;
  ASSERT_EQ(Fusionctl(address_, {"health"}, &out), 0) << out;
  EXPECT_NE(out.find("SERVING"), std::string::npos) << out;

  // Both sensors, as the compose services start them (no --frames: they run until stopped).
  const std::string domain = std::to_string(domain_);
  Subprocess sr3000({kTools + "fusion-sim-sensor", "--preset", "sr3000", "--rate", "5",
                     "--domain", domain, "--scene", "paper-board"});
  Subprocess stoc({kTools + "fusion-sim-sensor", "--preset", "stoc", "--rate", "5", "--domain",
                   domain, "--scene", "paper-board"});
  ASSERT_TRUE(sr3000.started());
  ASSERT_TRUE(stoc.started());

  // Both sensors' clouds get integrated.
  std::map<std::string, long> integrated;
  const auto end = std::chrono::steady_clock::now() + 30s;
  while (std::chrono::steady_clock::now() < end) {
    ASSERT_EQ(Fusionctl(address_, {"sensors"}, &out), 0) << out;
    integrated = IntegratedBySensor(out);
    if (integrated["sr3000"] >= 3 && integrated["stoc"] >= 3) break;
    std::this_thread::sleep_for(200ms);
  }
  EXPECT_GE(integrated["sr3000"], 3) << out;
  EXPECT_GE(integrated["stoc"], 3) << out;

  // The board: a plane facing the sensors (normal along x) at d = 1.75 m.
  std::vector<Plane> planes;
  bool found = false;
  while (!found && std::chrono::steady_clock::now() < end) {
    ASSERT_EQ(Fusionctl(address_, {"planes"}, &out), 0) << out;
    planes = ParsePlanes(out);
    for (const auto& p : planes) {
      found |= std::abs(std::abs(p.nx) - 1.0) < 0.02 && std::abs(p.d - 1.75) < 0.05;
    }
    if (!found) std::this_thread::sleep_for(300ms);
  }
  EXPECT_TRUE(found) << "no plane with normal (1, 0, 0) at d = 1.75 m in:\n" << out;
  EXPECT_NE(out.find("planes"), std::string::npos) << out;

  ASSERT_EQ(Fusionctl(address_, {"stats"}, &out), 0) << out;
  EXPECT_NE(out.find("resolution_m       0.020"), std::string::npos) << out;

  // Everything stops cleanly, as `docker compose down` would stop it (SIGTERM).
  EXPECT_EQ(sr3000.Stop(SIGTERM, 10000ms), 0);
  EXPECT_EQ(stoc.Stop(SIGTERM, 10000ms), 0);
  EXPECT_EQ(fusiond_->Stop(SIGTERM, 20000ms), 0);
  EXPECT_TRUE(fs::exists(dir_ + "/map.ot")) << "the final snapshot goes to --snapshot";
}

}  // namespace
