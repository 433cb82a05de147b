// DDS Security end to end (issue 15, item 2): fusiond runs with Cyclone's own security plugins
// and the files scripts/make_dds_security.sh makes per test. A sensor with an identity from the
// trusted CA and permission to publish is integrated; a publisher without security, one with an
// identity from another CA, and one whose valid identity may only subscribe are not. fusiond's
// counters say why: only one DDS writer ever matched its reader, and the others' clouds were
// neither received nor rejected (they never arrived); the publishers' own output says what DDS
// told them (no matched reader; writer creation not allowed by security).
#include <dlfcn.h>
#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <regex>
#include <sstream>

#include "../support/e2e_service.h"
#include "fusion/dds/participant.h"

namespace {

using namespace fusion::testing;  // NOLINT: the tools' paths and Subprocess
using namespace std::chrono_literals;
namespace v1 = fusion::v1;
namespace fs = std::filesystem;

constexpr int kFrames = 5;
// fusion-sim-sensor's --wait-readers timeout: a publisher DDS refuses waits this long.
constexpr auto kReaderWait = 10s;

std::string ReadFile(const std::string& path) {
  std::ifstream in(path);
  std::stringstream buffer;
  buffer << in.rdbuf();
  return buffer.str();
}

// Why the security plugins a generated configuration names cannot load ("" if they all do):
// each library must open and export its init function.
std::string PluginLoadError(const std::string& config_path) {
  const std::string xml = ReadFile(config_path);
  const std::regex library(R"re(<Library path="([^"]+)" initFunction="([^"]+)")re");
  int found = 0;
  for (std::sregex_iterator it(xml.begin(), xml.end(), library), end; it != end; ++it, ++found) {
    void* handle = dlopen((*it)[1].str().c_str(), RTLD_NOW | RTLD_LOCAL);
    if (handle == nullptr) return std::string("dlopen: ") + dlerror();
    const bool has_init = dlsym(handle, (*it)[2].str().c_str()) != nullptr;
    dlclose(handle);
    if (!has_init) return (*it)[1].str() + " has no " + (*it)[2].str();
  }
  return found == 3 ? "" : config_path + " names " + std::to_string(found) + " plugins, not 3";
}

class FusiondDdsSecurityTest : public E2eService {
 protected:
  void SetUp() override {
    E2eService::SetUp();
    trusted_ = dir_ + "/trusted";
    std::string error;
    const int code = MakeSecurity(trusted_, "sr3000", &error);
    if (code != 0 && error.find("libdds_security_") != std::string::npos) {
      GTEST_SKIP() << "Cyclone's security plugins are not installed: " << error;
    }
    ASSERT_EQ(code, 0) << error;
    if (const std::string load = PluginLoadError(Uri("fusiond")); !load.empty()) {
      GTEST_SKIP() << "Cyclone's security plugins do not load here: " << load;
    }
  }

  // Runs make_dds_security.sh DIR SENSOR; returns its exit code, its stderr in *error.
  int MakeSecurity(const std::string& dir, const std::string& sensor, std::string* error) {
    const std::string err = dir_ + "/make_dds_security.err";
    const std::string command = kRepoDir + "/scripts/make_dds_security.sh '" + dir + "' " + sensor +
                                " > /dev/null 2> '" + err + "'";
    const int status = std::system(command.c_str());
    *error = ReadFile(err);
    return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  }

  std::string Uri(const std::string& identity, const std::string& dir = "") const {
    return (dir.empty() ? trusted_ : dir) + "/dds_" + identity + ".xml";
  }

  // fusiond with two sensors of the same model: the authorised "sr3000" and "intruder", so
  // an intruder's cloud that arrived would be valid and integrated. `uri` "" is the embedded
  // loopback configuration.
  void StartFusiondWith(const std::string& uri) {
    const std::string config = dir_ + "/fusiond.pbtxt";
    std::ofstream(config) << "dds_domain: " << domain_ << "\nlog_level: \"warn\"\n"
                          << "sensors { id: \"sr3000\" preset: \"sr3000\" cols: 44 rows: 36 }\n"
                          << "sensors { id: \"intruder\" preset: \"sr3000\" cols: 44 rows: 36 }\n"
                          << "ingest { reliability: \"reliable\" }\n";
    fusiond_ = std::make_unique<Subprocess>(
        std::vector<std::string>{kBuildDir + "/service/fusiond", "--config", config, "--listen",
                                 "127.0.0.1:0"},
        std::vector<std::string>{"CYCLONEDDS_URI=" + (uri.empty() ? "" : "file://" + uri)});
    ASSERT_TRUE(fusiond_->started());
    const auto port = fusiond_->WaitForOutput(R"(fusiond listening on 127\.0\.0\.1:(\d+))", 20s);
    ASSERT_TRUE(port) << "no 'listening' line: " << fusiond_->output();
    stub_ = v1::FusionMap::NewStub(
        grpc::CreateChannel("127.0.0.1:" + *port, grpc::InsecureChannelCredentials()));
  }

  // fusion-sim-sensor publishing kFrames reliable frames as `sensor_id` with the DDS
  // configuration `uri` ("": the embedded one), its stderr merged into its stdout.
  std::unique_ptr<Subprocess> StartSensor(const std::string& uri, const std::string& sensor_id) {
    const std::string command = "exec '" + kToolsDir + "fusion-sim-sensor' --preset sr3000" +
                                " --cols 44 --rows 36 --sensor-id " + sensor_id + " --domain " +
                                std::to_string(domain_) + " --frames " + std::to_string(kFrames) +
                                " --rate 20 --reliable --wait-readers 1 2>&1";
    auto sensor = std::make_unique<Subprocess>(
        std::vector<std::string>{"/bin/sh", "-c", command},
        std::vector<std::string>{"CYCLONEDDS_URI=" + (uri.empty() ? "" : "file://" + uri)});
    EXPECT_TRUE(sensor->started());
    return sensor;
  }

  // Waits for a sensor to finish; returns its exit code and its output in *output.
  static int Finish(Subprocess& sensor, std::string* output) {
    sensor.WaitForOutput("(?!)", kReaderWait + 10s);  // drains the output until it exits
    *output = sensor.output();
    return sensor.Wait(5s);
  }

  // Waits until `sensor_id` has `n` clouds integrated (or 10 s pass).
  void WaitIntegrated(const std::string& sensor_id, std::uint64_t n) {
    const auto end = std::chrono::steady_clock::now() + 10s;
    while (Counters(sensor_id).integrated() < n && std::chrono::steady_clock::now() < end) {
      std::this_thread::sleep_for(20ms);
    }
  }

  std::string trusted_;
};

TEST_F(FusiondDdsSecurityTest, AuthorisedSensorIsIntegratedOthersAreNot) {
  const std::string rogue = dir_ + "/rogue";  // the same script, other CAs
  std::string error;
  ASSERT_EQ(MakeSecurity(rogue, "intruder", &error), 0) << error;
  StartFusiondWith(Uri("fusiond"));

  // All at once: the refused ones wait kReaderWait for a reader before publishing anyway.
  auto authorised = StartSensor(Uri("sr3000"), "sr3000");
  auto plain = StartSensor("", "intruder");
  auto foreign_ca = StartSensor(Uri("intruder", rogue), "intruder");
  auto subscriber_only = StartSensor(Uri("fusiond"), "intruder");  // fusiond's own identity

  const std::string published = "published " + std::to_string(kFrames) + " frames";
  const std::string no_reader = "only 0 readers after 10 s";
  std::string out;
  EXPECT_EQ(Finish(*authorised, &out), 0) << out;
  EXPECT_NE(out.find(published), std::string::npos) << out;
  EXPECT_EQ(out.find(no_reader), std::string::npos)
      << "the authorised sensor matched no reader: " << out;
  for (auto* refused : {plain.get(), foreign_ca.get()}) {
    EXPECT_EQ(Finish(*refused, &out), 0) << out;
    EXPECT_NE(out.find(no_reader), std::string::npos) << "a refused publisher matched: " << out;
    EXPECT_NE(out.find(published), std::string::npos) << out;
  }
  EXPECT_NE(Finish(*subscriber_only, &out), 0) << out;
  EXPECT_NE(out.find("dds_create_writer: Not Allowed By Security"), std::string::npos) << out;

  WaitIntegrated("sr3000", kFrames);
  const auto sr3000 = Counters("sr3000");
  EXPECT_EQ(sr3000.received(), std::uint64_t{kFrames});
  EXPECT_EQ(sr3000.integrated(), std::uint64_t{kFrames});
  // The refused publishers' clouds (valid, for a configured sensor) never arrived: not
  // received, not rejected by fusiond's validation, and their writers never matched.
  const auto intruder = Counters("intruder");
  EXPECT_EQ(intruder.received(), 0u);
  EXPECT_EQ(intruder.rejected(), 0u);
  const auto stats = Stats();
  EXPECT_EQ(stats.clouds_received(), std::uint64_t{kFrames});
  EXPECT_EQ(stats.clouds_rejected(), 0u);
  EXPECT_EQ(stats.matched_writers_total(), 1u) << "only the authorised sensor's writer matches";
  EXPECT_EQ(fusiond_->Stop(SIGTERM, 10s), 0);
}

// The control: the same unsecured publisher, against a fusiond without DDS Security, matches
// and is integrated (the issue's "foreign publisher"), and the counters show it.
TEST_F(FusiondDdsSecurityTest, WithoutSecurityTheSamePublisherIsIntegrated) {
  StartFusiondWith("");
  auto plain = StartSensor("", "intruder");
  std::string out;
  EXPECT_EQ(Finish(*plain, &out), 0) << out;
  EXPECT_EQ(out.find("only 0 readers"), std::string::npos) << out;
  WaitIntegrated("intruder", kFrames);
  EXPECT_EQ(Counters("intruder").integrated(), std::uint64_t{kFrames});
  EXPECT_EQ(Stats().matched_writers_total(), 1u);
  EXPECT_EQ(fusiond_->Stop(SIGTERM, 10s), 0);
}

// The configurations the script writes keep fusiond's embedded loopback settings exactly; the
// security-only files hold the same <Security> block.
TEST_F(FusiondDdsSecurityTest, ScriptKeepsTheLoopbackSettings) {
  const std::regex security(R"(\s*<Security>[\s\S]*</Security>)");
  for (const std::string identity : {"fusiond", "sr3000"}) {
    std::string xml = ReadFile(Uri(identity));
    std::smatch block, alone;
    const std::string only = ReadFile(trusted_ + "/security_" + identity + ".xml");
    ASSERT_TRUE(std::regex_search(xml, block, security)) << identity;
    ASSERT_TRUE(std::regex_search(only, alone, security)) << identity;
    EXPECT_EQ(block.str(), alone.str()) << identity;
    xml = std::regex_replace(xml, security, "");
    xml = std::regex_replace(xml, std::regex(R"(\n\s*)"), "");
    EXPECT_EQ(xml, fusion::dds::kLoopbackDdsConfig) << identity;
  }
}

TEST_F(FusiondDdsSecurityTest, ScriptRefusesAnExistingCaBadNamesAndMissingPlugins) {
  std::string error;
  EXPECT_EQ(MakeSecurity(trusted_, "sr3000", &error), 1);
  EXPECT_NE(error.find("identity_ca.key exists"), std::string::npos) << error;
  EXPECT_EQ(MakeSecurity(dir_ + "/other", "'bad name'", &error), 2);
  EXPECT_NE(error.find("bad identity name 'bad name'"), std::string::npos) << error;
  EXPECT_FALSE(fs::exists(dir_ + "/other/identity_ca.key"));
  ASSERT_EQ(setenv("FUSION_DDS_SECURITY_LIB", "/nonexistent", 1), 0);
  EXPECT_EQ(MakeSecurity(dir_ + "/other", "sr3000", &error), 1);
  unsetenv("FUSION_DDS_SECURITY_LIB");
  EXPECT_NE(error.find("no /nonexistent/libdds_security_auth.so"), std::string::npos) << error;
  EXPECT_FALSE(fs::exists(dir_ + "/other/identity_ca.key"));
}

}  // namespace
