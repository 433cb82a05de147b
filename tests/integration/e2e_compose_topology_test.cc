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

#include "../support/e2e_service.h"
#include "fusion/v1/map_service.grpc.pb.h"

namespace {

using fusion::testing::E2eService;
using fusion::testing::RunTool;
using fusion::testing::Subprocess;
using namespace std::chrono_literals;
namespace v1 = fusion::v1;
namespace fs = std::filesystem;

// Runs fusionctl against `server`; returns its exit code and stdout. Each command's default
// deadline applies: `planes` is an expensive call on fusiond's low-priority pool (fusionctl
// waits up to 120 s for it): under sanitizers, with both sensors streaming, it takes tens of
// seconds.
int Fusionctl(const std::string& server, std::vector<std::string> args, std::string* out) {
  std::vector<std::string> argv = {"fusionctl", "--server", server};
  argv.insert(argv.end(), args.begin(), args.end());
  return RunTool(argv, out, 150s);
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
      planes.push_back(
          {std::stod(m[1]), std::stod(m[2]), std::stod(m[3]), std::stod(m[4]), std::stol(m[5])});
    }
  }
  return planes;
}

class E2eComposeTopologyTest : public E2eService {};

TEST_F(E2eComposeTopologyTest, SensorsFusiondAndClientMapTheBoard) {
  const std::string config = fusion::testing::kRepoDir + "/docker/fusiond.pbtxt";
  ASSERT_TRUE(fs::exists(config)) << config << " (the compose deployment's configuration)";
  // The container's address, domain and volume would not do here: the flags override them.
  ASSERT_NO_FATAL_FAILURE(StartFusiondWithFile(config, {"--snapshot", dir_ + "/map.ot"}));

  // The client's health check, as compose's healthcheck runs it.
  std::string out;
  ASSERT_EQ(Fusionctl(address_, {"health"}, &out), 0) << out;
  EXPECT_NE(out.find("SERVING"), std::string::npos) << out;

  // Both sensors, as the compose services start them (no --frames: they run until stopped).
  const std::string domain = std::to_string(domain_);
  Subprocess sr3000({fusion::testing::kToolsDir + "fusion-sim-sensor", "--preset", "sr3000",
                     "--rate", "5", "--domain", domain, "--scene", "paper-board"});
  Subprocess stoc({fusion::testing::kToolsDir + "fusion-sim-sensor", "--preset", "stoc", "--rate",
                   "5", "--domain", domain, "--scene", "paper-board"});
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
  const auto planes_end = std::chrono::steady_clock::now() + 120s;
  while (!found && std::chrono::steady_clock::now() < planes_end) {
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
  EXPECT_NE(out.find("resolution_m         0.020\n"), std::string::npos) << out;

  // While the sensors stream, `watch --versions-only` announces new versions, ascending.
  ASSERT_EQ(Fusionctl(address_, {"watch", "--count", "3", "--versions-only"}, &out), 0) << out;
  {
    const std::regex line(R"(^version (\d+) \(from (\d+)\)$)");
    std::istringstream in(out);
    std::vector<unsigned long long> versions;
    for (std::string text; std::getline(in, text);) {
      std::smatch m;
      ASSERT_TRUE(std::regex_match(text, m, line)) << text;
      versions.push_back(std::stoull(m[1]));
    }
    ASSERT_EQ(versions.size(), 3u) << out;
    EXPECT_LT(versions[0], versions[1]) << out;
    EXPECT_LT(versions[1], versions[2]) << out;
  }

  // Everything stops cleanly, as `docker compose down` would stop it (SIGTERM).
  EXPECT_EQ(sr3000.Stop(SIGTERM, 10000ms), 0);
  EXPECT_EQ(stoc.Stop(SIGTERM, 10000ms), 0);
  EXPECT_EQ(fusiond_->Stop(SIGTERM, 20000ms), 0);
  EXPECT_TRUE(fs::exists(dir_ + "/map.ot")) << "the final snapshot goes to --snapshot";
}

}  // namespace
