// The compose deployment (docker/compose.yaml) is a valid compose file with the expected
// services. Needs docker-compose (v1, validates offline); skipped without it.
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <iterator>
#include <string>

namespace {

// The repository root: FUSION_SHARED_DATA_DIR is "<repo>/../shared/data".
std::string RepoDir() {
  std::string dir = FUSION_SHARED_DATA_DIR;
  const std::string suffix = "/../shared/data";
  return dir.substr(0, dir.size() - suffix.size());
}

// Runs a shell command; returns its exit status and combined output.
int Shell(const std::string& command, std::string* output) {
  FILE* pipe = popen((command + " 2>&1").c_str(), "r");
  if (pipe == nullptr) return -1;
  char buffer[4096];
  size_t n = 0;
  while ((n = fread(buffer, 1, sizeof buffer, pipe)) > 0) output->append(buffer, n);
  const int status = pclose(pipe);
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

class ComposeTest : public ::testing::Test {
 protected:
  void SetUp() override {
    std::string out;
    if (Shell("command -v docker-compose", &out) != 0) {
      GTEST_SKIP() << "docker-compose is not installed (apt-get install --no-install-recommends "
                      "docker-compose)";
    }
    compose_ = RepoDir() + "/docker/compose.yaml";
    ASSERT_TRUE(std::ifstream(compose_).good()) << compose_ << " is missing";
  }
  std::string compose_;
};

TEST_F(ComposeTest, ConfigIsValid) {
  std::string out;
  EXPECT_EQ(Shell("docker-compose -f '" + compose_ + "' config -q", &out), 0) << out;
}

TEST_F(ComposeTest, HasTheServicesAndHealthCheck) {
  std::string services;
  ASSERT_EQ(Shell("docker-compose -f '" + compose_ + "' config --services", &services), 0)
      << services;
  for (const char* name :
       {"certs", "fusiond", "sensor-sr3000", "sensor-stoc", "client", "prometheus"}) {
    EXPECT_NE(services.find(name), std::string::npos) << name << " missing in:\n" << services;
  }
  std::string config;
  ASSERT_EQ(Shell("docker-compose -f '" + compose_ + "' config", &config), 0) << config;
  EXPECT_NE(config.find("health"), std::string::npos);
  EXPECT_NE(config.find("CYCLONEDDS_URI"), std::string::npos);
  // gRPC with TLS and tokens, and clients that present them.
  for (const char* needed :
       {"--tls-cert", "--tokens-file", "FUSION_TLS_CA", "FUSION_TOKEN_FILE", "--metrics-listen"}) {
    EXPECT_NE(config.find(needed), std::string::npos) << needed;
  }
}

// Profile ros2: fusiond on the host's network with the host DDS configuration and its domain
// from ROS_DOMAIN_ID; fusiond has time to write its final snapshot before Docker kills it.
TEST_F(ComposeTest, Ros2ProfileSharesTheHostNetworkAndStopsAreGraceful) {
  std::string config;
  ASSERT_EQ(
      Shell("ROS_DOMAIN_ID=17 docker-compose -f '" + compose_ + "' --profile ros2 config", &config),
      0)
      << config;
  const auto ros2 = config.find("  fusiond-ros2:\n");
  ASSERT_NE(ros2, std::string::npos) << config;
  // Up to the next service (a line indented by two spaces only).
  std::size_t next = ros2 + 1;
  do {
    next = config.find("\n  ", next + 1);
  } while (next != std::string::npos && config.compare(next + 3, 1, " ") == 0);
  const std::string service = config.substr(ros2, next - ros2);
  for (const char* needed : {"network_mode: host", "cyclonedds-host.xml", "fusiond-ros2.pbtxt",
                             "- '17'", "--tokens-file", "stop_grace_period: 60s"}) {
    EXPECT_NE(service.find(needed), std::string::npos) << needed << " missing in:\n" << service;
  }
  std::string services;
  ASSERT_EQ(Shell("docker-compose -f '" + compose_ + "' config", &services), 0) << services;
  const auto fusiond = services.find("  fusiond:\n");
  ASSERT_NE(fusiond, std::string::npos);
  EXPECT_NE(services.find("stop_grace_period: 60s", fusiond), std::string::npos);
}

// The build context leaves build trees and .git out (/.dockerignore).
TEST_F(ComposeTest, DockerignoreKeepsBuildTreesOutOfTheContext) {
  std::ifstream in(RepoDir() + "/.dockerignore");
  ASSERT_TRUE(in.good()) << "no .dockerignore at the repository root";
  std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  for (const char* line : {"\nbuild*\n", "\n.git\n"}) {
    EXPECT_NE(text.find(line), std::string::npos) << line;
  }
}

TEST_F(ComposeTest, BrokenFileIsRejected) {
  // The validation itself can fail: a service without image or build.
  const std::string path = ::testing::TempDir() + "/broken_compose.yaml";
  std::ofstream(path) << "services:\n  x:\n    command: [true]\n    ports: {bad: mapping}\n";
  std::string out;
  EXPECT_NE(Shell("docker-compose -f '" + path + "' config -q", &out), 0) << out;
  std::remove(path.c_str());
}

}  // namespace
