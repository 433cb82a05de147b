// Every client tool's command line is strict: an unknown option or an extra argument is a usage
// error (exit 2) before any work, and --help exits 0.
#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "../support/e2e_service.h"

namespace {

using fusion::testing::RunTool;

struct Line {
  std::vector<std::string> argv;
  int exit_code;
};

void ExpectExitCodes(const std::vector<Line>& lines) {
  for (const auto& line : lines) {
    std::string out;
    EXPECT_EQ(RunTool(line.argv, &out), line.exit_code) << ::testing::PrintToString(line.argv);
    if (line.exit_code == 0) {
      EXPECT_FALSE(out.empty()) << "--help prints the usage on stdout";
    }
  }
}

TEST(ClientsStrictFlagsTest, FusionReplay) {
  ExpectExitCodes({{{"fusion-replay", "--help"}, 0},
                   {{"fusion-replay", "r.frec", "--bogus"}, 2},
                   {{"fusion-replay", "r.frec", "extra.frec"}, 2},
                   {{"fusion-replay", "r.frec", "--rate"}, 2}});
}

TEST(ClientsStrictFlagsTest, FusionRecord) {
  ExpectExitCodes({{{"fusion-record", "--help"}, 0},
                   {{"fusion-record", "-o", "x.frec", "--bogus"}, 2},
                   {{"fusion-record", "-o", "x.frec", "extra"}, 2},
                   {{"fusion-record", "-o", "x.frec", "--domain", "999"}, 2}});
}

TEST(ClientsStrictFlagsTest, FusionImport) {
  ExpectExitCodes({{{"fusion-import", "--help"}, 0},
                   {{"fusion-import", "tum", "--help"}, 0},
                   {{"fusion-import", "nosuch", "dir", "-o", "x.frec"}, 2},
                   {{"fusion-import", "tum", "dir", "-o", "x.frec", "--bogus"}, 2},
                   {{"fusion-import", "tum", "dir", "extra", "-o", "x.frec"}, 2},
                   {{"fusion-import", "graph", "a.graph", "b.graph", "-o", "x.frec"}, 2},
                   {{"fusion-import", "pcd", "a.pcd", "-o", "x.frec", "--stride", "2"}, 2}});
}

TEST(ClientsStrictFlagsTest, FusionSimSensor) {
  ExpectExitCodes({{{"fusion-sim-sensor", "--help"}, 0},
                   {{"fusion-sim-sensor", "--preset", "sr3000", "--bogus", "1"}, 2},
                   {{"fusion-sim-sensor", "--preset", "sr3000", "--no-such-flag"}, 2},
                   {{"fusion-sim-sensor", "--preset", "sr3000", "--rate"}, 2},
                   {{"fusion-sim-sensor", "--preset", "sr3000", "extra"}, 2},
                   {{"fusion-sim-sensor", "--preset", "sr3000", "--frames", "x"}, 2}});
}

}  // namespace
