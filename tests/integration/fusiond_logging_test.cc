// fusiond's JSON log end to end (issue 15, item 4): with log_format "json" every line of its
// stderr is one JSON object, through a map built, a snapshot written at exit and loaded at the
// next start, and no foreign console line among them.
#include <gtest/gtest.h>

#include <fstream>

#include "../support/fusiond_fixture.h"
#include "../support/json_line.h"

namespace {

using namespace fusion::testing;  // NOLINT: the fixture and its helpers
using namespace std::chrono_literals;

TEST_F(FusiondServiceTest, JsonLogLinesAllParseThroughSnapshotWriteAndLoad) {
  std::string text;
  {
    std::ifstream in(config_);
    text.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  }
  const auto level = text.find("log_level: \"warn\"");
  ASSERT_NE(level, std::string::npos) << text;
  text.replace(level, std::string("log_level: \"warn\"").size(), "log_level: \"debug\"");
  std::ofstream(config_) << text << "log_format: \"json\"\n";
  const std::string log = dir_ + "/fusiond.log";
  {
    auto fusiond = Start(log);
    ASSERT_TRUE(fusiond);
    TestPublisher publisher(domain_);
    ASSERT_TRUE(publisher.WaitForReader(10s));
    ASSERT_GT(MapTheBoard(publisher), 0u);
    ASSERT_EQ(fusiond->Stop(SIGTERM, 15s), 0);  // writes the final snapshot
  }
  {
    auto fusiond = Start(log);  // loads it
    ASSERT_TRUE(fusiond);
    EXPECT_EQ(Occupancy(kOnBoard).state(), fusion::v1::VOXEL_STATE_OCCUPIED);
    ASSERT_EQ(fusiond->Stop(SIGTERM, 15s), 0);
  }
  std::ifstream in(log);
  int lines = 0;
  bool written = false, loaded = false;
  for (std::string line; std::getline(in, line); ++lines) {
    const auto object = ParseFlatJsonObject(line);
    ASSERT_TRUE(object) << "not a JSON line: " << line;
    for (const char* key : {"time", "level", "logger", "message", "pid", "thread"}) {
      EXPECT_EQ(object->count(key), 1u) << key << " missing: " << line;
    }
    const std::string message = object->count("message") ? object->at("message") : "";
    written |= message.find("snapshot: version") != std::string::npos &&
               message.find("written") != std::string::npos;
    loaded |= message.find("snapshot: loaded") != std::string::npos;
  }
  EXPECT_GT(lines, 10);
  EXPECT_TRUE(written);
  EXPECT_TRUE(loaded);
}

}  // namespace
