// fusion-import -> fusion-replay -> DDS (loopback, private domain) -> fusion-record, as
// separate processes, and the recordings compared record by record.
#include <gtest/gtest.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "../support/subprocess.h"

namespace {

using fusion::testing::Subprocess;
using std::chrono::milliseconds;
using std::chrono::seconds;

const std::string kTools = std::string(FUSION_BINARY_DIR) + "/clients/";

std::string TempPath(const std::string& name) {
  return ::testing::TempDir() + "/clients_rr_" + std::to_string(getpid()) + "_" + name;
}

// Runs a tool to completion; returns its exit code and stdout.
int RunTool(std::vector<std::string> argv, std::string* out = nullptr,
            seconds timeout = seconds(60)) {
  argv[0] = kTools + argv[0];
  Subprocess process(argv);
  if (!process.started()) return -1;
  process.WaitForOutput("(?!)", timeout);  // drains stdout until the child exits
  const int code = process.Wait(milliseconds(5000));
  if (out) *out = process.output();
  return code;
}

// Five small PCD files (a 4x3 organized cloud each, one NaN), imported into one recording
// whose clouds are `period_s` apart.
std::string MakeRecording(const std::string& name, double period_s) {
  std::vector<std::string> argv = {"fusion-import",
                                   "pcd",
                                   "--sensor-id",
                                   "sr3000",
                                   "--start-time",
                                   "1700000000.5",
                                   "--period",
                                   std::to_string(period_s),
                                   "-o",
                                   TempPath(name)};
  for (int f = 0; f < 5; ++f) {
    const std::string path = TempPath(name + std::to_string(f) + ".pcd");
    std::ofstream out(path);
    out << "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 4\nHEIGHT 3\n"
        << "VIEWPOINT " << f << " 0 0.5 1 0 0 0\nPOINTS 12\nDATA ascii\n";
    for (int i = 0; i < 12; ++i) {
      if (i == f) {
        out << "nan nan nan\n";
      } else {
        out << f + 0.25 * i << " " << -0.5 + 0.1 * i << " " << 1.5 + 0.01 * f << "\n";
      }
    }
    argv.push_back(path);
  }
  std::string out;
  EXPECT_EQ(RunTool(argv, &out), 0) << out;
  return TempPath(name);
}

// fusion-replay --list without its first line (which names the file and the writer).
std::vector<std::string> List(const std::string& recording) {
  std::string out;
  EXPECT_EQ(RunTool({"fusion-replay", "--list", recording}, &out), 0) << out;
  std::vector<std::string> lines;
  std::istringstream stream(out);
  for (std::string line; std::getline(stream, line);) {
    if (!line.empty() && line[0] != '#') lines.push_back(line);
  }
  return lines;
}

TEST(ClientsRecordReplayTest, ReliableFastReplayIsRecordedIdentically) {
  const std::string domain = std::to_string(fusion::testing::PrivateDomainId());
  const std::string input = MakeRecording("in.frec", 0.2);
  const std::string output = TempPath("out.frec");

  Subprocess recorder({kTools + "fusion-record", "-o", output, "--domain", domain, "--reliable",
                       "--count", "5", "--quiet"});
  ASSERT_TRUE(recorder.started());
  ASSERT_TRUE(recorder.WaitForOutput("subscribed to fusion/points", seconds(20)))
      << recorder.output();
  std::string replay_out;
  ASSERT_EQ(RunTool({"fusion-replay", input, "--domain", domain, "--fast", "--reliable",
                     "--wait-readers", "1", "--quiet"},
                    &replay_out),
            0)
      << replay_out;
  EXPECT_NE(replay_out.find("published 5 clouds"), std::string::npos) << replay_out;
  ASSERT_TRUE(recorder.WaitForOutput("recorded (\\d+) clouds to", seconds(20)))
      << recorder.output();
  EXPECT_EQ(recorder.Wait(milliseconds(10000)), 0);
  EXPECT_NE(recorder.output().find("recorded 5 clouds"), std::string::npos) << recorder.output();

  const std::vector<std::string> sent = List(input);
  const std::vector<std::string> received = List(output);
  ASSERT_EQ(sent.size(), 5u);
  EXPECT_EQ(received, sent);
  // The poses come from VIEWPOINT (tx = file number) and survive the trip.
  EXPECT_NE(received[3].find("pose=3.000000,0.000000,0.500000"), std::string::npos) << received[3];
}

TEST(ClientsRecordReplayTest, BrokenRecordStopsReplayAfterEverythingBeforeIt) {
  const std::string domain = std::to_string(fusion::testing::PrivateDomainId(1));
  const std::string input = MakeRecording("broken.frec", 0.2);
  // Corrupt a byte near the end of record 3's payload (records are equal-sized here).
  std::string bytes;
  {
    std::ifstream in(input, std::ios::binary);
    bytes.assign((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  }
  std::string list_out;
  ASSERT_EQ(RunTool({"fusion-replay", "--list", input}, &list_out), 0);
  // Find record 3's frame by its sensor id occurrence (the 4th "sr3000" in the file).
  std::size_t pos = 0;
  for (int k = 0; k < 4; ++k) pos = bytes.find("sr3000", pos + 1);
  ASSERT_NE(pos, std::string::npos);
  bytes[pos + 40] ^= 0x01;
  {
    std::ofstream out(input, std::ios::binary | std::ios::trunc);
    out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  }

  const std::string output = TempPath("broken_out.frec");
  Subprocess recorder(
      {kTools + "fusion-record", "-o", output, "--domain", domain, "--reliable", "--quiet"});
  ASSERT_TRUE(recorder.WaitForOutput("subscribed", seconds(20))) << recorder.output();
  std::string replay_out;
  EXPECT_EQ(RunTool({"fusion-replay", input, "--domain", domain, "--fast", "--reliable", "--quiet"},
                    &replay_out),
            1)
      << replay_out;
  // SIGINT ends the recorder cleanly, with the index written.
  EXPECT_EQ(recorder.Stop(SIGINT, milliseconds(10000)), 0);
  EXPECT_EQ(recorder.WaitForOutput("recorded (\\d+) clouds to", seconds(5)).value_or("none"), "3")
      << recorder.output();
  const std::vector<std::string> received = List(output);
  ASSERT_EQ(received.size(), 3u);
  EXPECT_EQ(received[2].rfind("2 sensor=sr3000 seq=3", 0), 0u) << received[2];

  std::string out;
  EXPECT_EQ(RunTool({"fusion-replay", "--list", input}, &out), 1);
}

TEST(ClientsRecordReplayTest, ReplayKeepsTheRecordedPaceUnlessFast) {
  const std::string domain = std::to_string(fusion::testing::PrivateDomainId(2));
  const std::string input = MakeRecording("paced.frec", 0.25);  // 1.0 s from first to last
  const auto time_replay = [&](std::vector<std::string> extra) {
    std::vector<std::string> argv = {"fusion-replay",  input, "--domain", domain,
                                     "--wait-readers", "0",   "--quiet"};
    argv.insert(argv.end(), extra.begin(), extra.end());
    const auto start = std::chrono::steady_clock::now();
    EXPECT_EQ(RunTool(argv), 0);
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  };
  // Pacing waits between clouds: the original pace takes the recording's 1.0 s at least, twice
  // the rate half of it. The upper bounds are relative to the paced run, so that a slow or
  // busy machine (start-up, DDS discovery) shifts every run alike.
  const double paced = time_replay({});
  const double fast = time_replay({"--fast"});
  const double doubled = time_replay({"--rate", "2"});
  EXPECT_GE(paced, 0.95);
  EXPECT_GE(doubled, 0.45);
  EXPECT_LT(fast + 0.5, paced) << "--fast should skip the 1 s of waiting";
  EXPECT_LT(doubled + 0.25, paced) << "--rate 2 should skip half of the waiting";
}

TEST(ClientsSimSensorTest, SimulatedFramesAreRecorded) {
  if (access((kTools + "fusion-sim-sensor").c_str(), X_OK) != 0) {
    GTEST_SKIP() << "fusion-sim-sensor not built (needs core/sim)";
  }
  const std::string domain = std::to_string(fusion::testing::PrivateDomainId(3));
  const std::string output = TempPath("sim.frec");
  Subprocess recorder({kTools + "fusion-record", "-o", output, "--domain", domain, "--reliable",
                       "--count", "3", "--quiet"});
  ASSERT_TRUE(recorder.WaitForOutput("subscribed", seconds(20))) << recorder.output();
  std::string out;
  ASSERT_EQ(RunTool({"fusion-sim-sensor", "--preset", "sr3000", "--domain", domain, "--rate", "20",
                     "--frames", "3", "--reliable", "--wait-readers", "1", "--pose", "0,0,0,0,5"},
                    &out),
            0)
      << out;
  ASSERT_TRUE(recorder.WaitForOutput("recorded (\\d+) clouds to", seconds(20)));
  const std::vector<std::string> received = List(output);
  ASSERT_EQ(received.size(), 3u);
  for (std::size_t i = 0; i < 3; ++i) {
    EXPECT_NE(received[i].find("sensor=sr3000 seq=" + std::to_string(i + 1)), std::string::npos)
        << received[i];
    EXPECT_NE(received[i].find("size=176x144"), std::string::npos) << received[i];
    EXPECT_NE(received[i].find("beyond_range=25344"), std::string::npos) << received[i];
  }
  EXPECT_EQ(RunTool({"fusion-sim-sensor", "--preset", "nonsense"}), 2);
}

TEST(ClientsToolsTest, HelpAndBadArguments) {
  for (const char* tool : {"fusion-import", "fusion-record", "fusion-replay"}) {
    std::string out;
    EXPECT_EQ(RunTool({tool, "--help"}, &out), 0) << tool;
    EXPECT_NE(out.find("Usage"), std::string::npos) << tool << ": " << out;
  }
  for (const char* sub : {"tum", "pcd", "graph", "scan"}) {
    std::string out;
    EXPECT_EQ(RunTool({"fusion-import", sub, "--help"}, &out), 0) << sub;
    EXPECT_NE(out.find("-o, --output"), std::string::npos) << sub << ": " << out;
  }
  EXPECT_EQ(RunTool({"fusion-import", "nonsense"}), 2);
  EXPECT_EQ(RunTool({"fusion-import", "tum", "/nonexistent", "-o", TempPath("x.frec")}), 1);
  EXPECT_EQ(RunTool({"fusion-replay", "--rate", "-1", "x.frec"}), 2);
  EXPECT_EQ(RunTool({"fusion-replay", "/nonexistent.frec"}), 1);
  EXPECT_EQ(RunTool({"fusion-record"}), 2);
  EXPECT_EQ(RunTool({"fusion-record", "-o", TempPath("y.frec"), "--domain", "999"}), 2);
}

}  // namespace
