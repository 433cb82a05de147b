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
#include <cstdio>
#include <filesystem>
#include <fstream>
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

const std::string kPython = "/usr/bin/python3";

// Runs path_check.py; returns its exit code and stdout + stderr.
int PathCheck(const std::string& server, const std::string& from, const std::string& to,
              std::string* out, const std::string& extra = "") {
  const std::string log = ::testing::TempDir() + "path_check_" + std::to_string(getpid()) + ".log";
  Subprocess process({"/bin/sh", "-c",
                      "exec " + kPython + " " + fusion::testing::kRepoDir +
                          "/clients/python/path_check.py --server " + server + " --from " + from +
                          " --to " + to + " --timeout 3 " + extra + " 2>&1"},
                     {"PYTHONPATH=" + fusion::testing::kBuildDir + "/clients/python"});
  process.WaitForOutput("(?!)", 30s);
  const int code = process.Wait(5000ms);
  *out = process.output();
  std::printf("path_check %s -> %s: exit %d: %s", from.c_str(), to.c_str(), code, out->c_str());
  return code;
}

class E2ePythonClientTest : public E2eService {
 protected:
  void SetUp() override {
    if (access(kPython.c_str(), X_OK) != 0) GTEST_SKIP() << kPython << " is not installed";
    if (std::system((kPython + " -c 'import grpc, google.protobuf' 2>/dev/null").c_str()) != 0) {
      GTEST_SKIP() << kPython << " lacks grpc (apt-get install python3-grpcio python3-protobuf)";
    }
    if (!fs::exists(fusion::testing::kBuildDir +
                    "/clients/python/fusion/v1/map_service_pb2_grpc.py")) {
      GTEST_SKIP() << "no Python stubs in " << fusion::testing::kBuildDir
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
  ASSERT_TRUE(WaitInMap(10, 30s)) << "integrated " << Counters("sr3000").integrated() << " of 10";

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

// The same client against a fusiond with TLS and bearer tokens (docs/security.md).
TEST_F(E2ePythonClientTest, PathCheckSpeaksTlsWithAToken) {
  const std::string certs = ::testing::TempDir() + "python_tls_" + std::to_string(getpid());
  fs::remove_all(certs);
  ASSERT_EQ(std::system((fusion::testing::kRepoDir + "/scripts/make_certs.sh " + certs +
                         " > /dev/null")
                            .c_str()),
            0);
  ASSERT_NO_FATAL_FAILURE(StartFusiond(
      "log_level: \"warn\"\n"
      "sensors { id: \"sr3000\" preset: \"sr3000\" }\n"
      "map { resolution_m: 0.05 }\n"
      "security { tls_cert_file: \"" + certs + "/server.pem\" tls_key_file: \"" + certs +
      "/server.key\" tokens_file: \"" + certs + "/tokens\" }\n"));
  std::string out;
  // An empty map: a path through unknown space is clear unless unknown counts.
  EXPECT_EQ(PathCheck(address_, "0.5,0,0", "1.2,0,0", &out,
                      "--tls-ca " + certs + "/ca.pem --token-file " + certs + "/read.token"),
            0)
      << out;
  EXPECT_EQ(out.rfind("clear (", 0), 0u) << out;
  EXPECT_EQ(PathCheck(address_, "0.5,0,0", "1.2,0,0", &out, "--tls-ca " + certs + "/ca.pem"), 2)
      << out;  // no token: UNAUTHENTICATED
  EXPECT_NE(out.find("cannot query fusiond"), std::string::npos) << out;
  EXPECT_EQ(PathCheck(address_, "0.5,0,0", "1.2,0,0", &out), 2) << out;  // plaintext
  fs::remove_all(certs);
}

}  // namespace
