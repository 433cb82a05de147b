// The fusion-import binary on rosbag2 bags: exit codes, what it prints, and the recording a
// broken bag leaves (the clouds before the break, readable by RecordingReader).
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>

#include "bag_scene.h"
#include "fusion/clients/recording.h"

namespace fusion::clients {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;

const std::string kImport = std::string(FUSION_BINARY_DIR) + "/clients/fusion-import";

struct ToolRun {
  int exit_code;
  std::string out, err;
};

std::string Slurp(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

ToolRun Import(const std::string& dir, const std::string& args) {
  const int status = std::system(
      (kImport + " rosbag2 " + args + " >" + dir + "/out.txt 2>" + dir + "/err.txt").c_str());
  return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, Slurp(dir + "/out.txt"),
          Slurp(dir + "/err.txt")};
}

std::size_t RecordsIn(const std::string& path) {
  std::unique_ptr<RecordingReader> reader;
  if (!RecordingReader::Open(path, &reader).ok()) return 0;
  return reader->size();
}

class Rosbag2Cli : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = ::testing::TempDir() + "/rosbag2_cli_" + std::to_string(getpid());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
    mcap_ = test::SceneMcap(test::SceneEvents(), &chunks_);
    std::ofstream(dir_ + "/scene.mcap", std::ios::binary) << mcap_;
  }
  void TearDown() override { fs::remove_all(dir_); }

  std::string dir_, mcap_;
  std::vector<test::McapWriter::RecordStart> chunks_;
};

TEST_F(Rosbag2Cli, ImportsAndReportsSkips) {
  const ToolRun r =
      Import(dir_, dir_ + "/scene.mcap --points-topic /lidar/points -o " + dir_ + "/a.frec");
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_THAT(r.out, HasSubstr("imported 6 clouds (288 points)"));
  EXPECT_THAT(r.err, HasSubstr("1 clouds skipped: extrapolation"));
  EXPECT_EQ(RecordsIn(dir_ + "/a.frec"), 6u);
}

TEST_F(Rosbag2Cli, BrokenBagKeepsTheCloudsBeforeTheBreakAndFails) {
  std::ofstream(dir_ + "/cut.mcap", std::ios::binary) << mcap_.substr(0, chunks_[2].offset + 50);
  const ToolRun r =
      Import(dir_, dir_ + "/cut.mcap --points-topic /lidar/points -o " + dir_ + "/b.frec");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_THAT(r.err, HasSubstr("(Chunk) at byte " + std::to_string(chunks_[2].offset)));
  EXPECT_THAT(r.err, HasSubstr("keeps the 4 clouds imported before the error"));
  EXPECT_EQ(RecordsIn(dir_ + "/b.frec"), 4u);
}

TEST_F(Rosbag2Cli, BadCommandLinesExitTwo) {
  EXPECT_EQ(Import(dir_, dir_ + "/scene.mcap -o " + dir_ + "/c.frec").exit_code, 2);
  EXPECT_EQ(Import(dir_, dir_ + "/scene.mcap --points-topic /p --depth-topic /d -o x").exit_code,
            2);
  EXPECT_EQ(Import(dir_, dir_ + "/scene.mcap --points-topic /p --start-time 1 -o x").exit_code, 2);
  const ToolRun missing =
      Import(dir_, dir_ + "/scene.mcap --points-topic /p -o " + dir_ + "/d.frec");
  EXPECT_EQ(missing.exit_code, 1);
  EXPECT_THAT(missing.err,
              HasSubstr("/camera/depth/image_raw (sensor_msgs/msg/Image, 3 messages)"));
  EXPECT_FALSE(fs::exists(dir_ + "/d.frec"));
}

}  // namespace
}  // namespace fusion::clients
