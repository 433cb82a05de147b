// fusionctl (the built tool, as a process) against a real fusiond that maps the board from a
// simulated sensor: --json on every command parses as its documented message, `stats` shows
// clouds_in_map (what the README has users wait on), a bad command line changes nothing.
#include <google/protobuf/struct.pb.h>
#include <google/protobuf/util/json_util.h>
#include <gtest/gtest.h>

#include <chrono>
#include <filesystem>
#include <functional>
#include <memory>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "../support/e2e_service.h"
#include "fusion/v1/map_service.pb.h"
#include "grpc/health/v1/health.pb.h"

namespace {

using fusion::testing::E2eService;
using fusion::testing::RunTool;
using namespace std::chrono_literals;
namespace v1 = fusion::v1;
namespace pb = google::protobuf;

class FusionctlFusiondTest : public E2eService {
 protected:
  void SetUp() override {
    E2eService::SetUp();
    ASSERT_NO_FATAL_FAILURE(
        StartFusiond("log_level: \"warn\"\n"
                     "sensors { id: \"sr3000\" preset: \"sr3000\" cols: 44 rows: 36 }\n"
                     "map { resolution_m: 0.05 render_interval_ms: 100 }\n"
                     "ingest { reliability: \"reliable\" }\n"
                     "persistence { path: \"" +
                     dir_ + "/saved.ot\" interval_s: 3600 }\n"));
  }
  int Fusionctl(std::vector<std::string> args, std::string* out) {
    args.insert(args.begin(), {"fusionctl", "--server", address_});
    return RunTool(args, out, 150s);
  }
  // `frames` frames of the board from fusion-sim-sensor, then `fusionctl --json stats` until
  // clouds_in_map says the map holds them.
  void MapFrames(int frames) {
    std::string out;
    ASSERT_EQ(RunTool({"fusion-sim-sensor", "--preset", "sr3000", "--cols", "44", "--rows", "36",
                       "--frames", std::to_string(frames), "--rate", "20", "--reliable",
                       "--wait-readers", "1", "--domain", std::to_string(domain_)},
                      &out),
              0)
        << out;
    ASSERT_TRUE(WaitInMapWithFusionctl(frames)) << "clouds_in_map did not reach " << frames;
  }
  // `fusionctl --json stats` until clouds_in_map reaches `clouds`.
  bool WaitInMapWithFusionctl(std::uint64_t clouds) {
    const auto end = std::chrono::steady_clock::now() + 30s;
    while (std::chrono::steady_clock::now() < end) {
      std::string out;
      v1::Stats stats;
      if (Fusionctl({"--json", "stats"}, &out) == 0 &&
          pb::util::JsonStringToMessage(out, &stats).ok() && stats.clouds_in_map() >= clouds) {
        return true;
      }
      std::this_thread::sleep_for(100ms);
    }
    return false;
  }
};

TEST_F(FusionctlFusiondTest, JsonOfEveryCommandParsesAsItsMessage) {
  ASSERT_NO_FATAL_FAILURE(MapFrames(5));
  std::string out;

  ASSERT_EQ(Fusionctl({"stats"}, &out), 0);
  EXPECT_NE(out.find("clouds_in_map        5\n"), std::string::npos) << out;

  const std::string ot = dir_ + "/map.ot", png = dir_ + "/map.png";
  struct Case {
    std::vector<std::string> args;
    std::function<pb::Message*()> make;
  };
  const std::vector<Case> cases = {
      {{"health"}, [] { return new grpc::health::v1::HealthCheckResponse; }},
      {{"stats"}, [] { return new v1::Stats; }},
      {{"sensors"}, [] { return new v1::ListSensorsResponse; }},
      {{"points", "1.75,0,0.2", "1,0,0.2"}, [] { return new v1::QueryPointsResponse; }},
      {{"box", "1.5", "-0.3", "0", "2", "0.3", "0.4", "--state", "occupied"},
       [] { return new v1::QueryBoxResponse; }},
      {{"ray", "0", "0", "0.2", "1", "0", "0"}, [] { return new v1::CastRayResponse; }},
      {{"planes", "--max", "2"}, [] { return new v1::FindPlanesResponse; }},
      {{"beam", "sr3000", "18", "22"}, [] { return new v1::InspectBeamResponse; }},
      {{"snapshot", ot}, [] { return new pb::Struct; }},
      {{"render", png, "--size", "64x48"}, [] { return new pb::Struct; }},
      // Versions only: the whole map as one JSON line is megabytes, slow to drain through the
      // test's pipe reader (the unit test has watch with voxels).
      {{"watch", "--count", "1", "--versions-only"}, [] { return new v1::MapUpdate; }},
      {{"save"}, [] { return new v1::SaveMapResponse; }},
      {{"reset"}, [] { return new v1::ResetMapResponse; }},
  };
  for (const auto& c : cases) {
    auto args = c.args;
    args.insert(args.begin(), "--json");
    ASSERT_EQ(Fusionctl(args, &out), 0) << c.args[0];
    std::istringstream lines(out);
    int documents = 0;
    for (std::string line; std::getline(lines, line); ++documents) {
      std::unique_ptr<pb::Message> message(c.make());
      const auto s = pb::util::JsonStringToMessage(line, message.get());
      EXPECT_TRUE(s.ok()) << c.args[0] << ": " << s.ToString() << "\n" << line;
    }
    EXPECT_GE(documents, 1) << c.args[0];
    if (c.args[0] != "watch") {
      EXPECT_EQ(documents, 1) << c.args[0] << ":\n" << out;
    }
    if (c.args[0] == "box") {
      v1::QueryBoxResponse box;
      ASSERT_TRUE(pb::util::JsonStringToMessage(out, &box).ok());
      EXPECT_GT(box.voxels_size(), 0) << "the board is occupied";
    }
  }
  EXPECT_TRUE(std::filesystem::exists(ot));
  EXPECT_TRUE(std::filesystem::exists(png));
}

TEST_F(FusionctlFusiondTest, BadCommandLinesChangeNothing) {
  ASSERT_NO_FATAL_FAILURE(MapFrames(2));
  std::string out;
  const auto before = Stats();
  EXPECT_EQ(Fusionctl({"reset", "--yes-really"}, &out), 2);
  EXPECT_EQ(Fusionctl({"reset", "now"}, &out), 2);
  EXPECT_EQ(Fusionctl({"save", "--force"}, &out), 2);
  EXPECT_EQ(Fusionctl({"render", dir_ + "/map.jpg"}, &out), 2);
  EXPECT_FALSE(std::filesystem::exists(dir_ + "/map.jpg"));
  const auto after = Stats();
  EXPECT_EQ(after.map_version(), before.map_version()) << "the map was not reset";
  EXPECT_EQ(after.snapshots_saved(), before.snapshots_saved());
  EXPECT_EQ(after.renders(), before.renders());
}

}  // namespace
