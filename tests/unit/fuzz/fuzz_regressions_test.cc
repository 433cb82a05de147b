// Replays every input under tests/fuzz/regressions/<target>/ through the entry its fuzz target
// runs (tests/fuzz/fuzz_entries.h): each must be accepted consistently or refused with a
// message, never crash, and within bounded memory. The inputs are the crashes the fuzzers found
// and their relatives (README.md there, docs/fuzzing.md).
#include <gtest/gtest.h>
#include <octomap/OcTree.h>
#include <sys/resource.h>

#include <filesystem>
#include <fstream>
#include <iterator>
#include <set>
#include <sstream>
#include <string>

#include "fuzz_entries.h"

namespace fusion::fuzz {
namespace {

namespace fs = std::filesystem;
const fs::path kRegressions = FUSION_FUZZ_REGRESSIONS_DIR;

std::string Slurp(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

TEST(FuzzRegressionsTest, EveryFolderNamesATarget) {
  std::set<std::string> targets;
  for (const NamedEntry& e : AllEntries()) targets.insert(e.target);
  ASSERT_TRUE(fs::is_directory(kRegressions)) << kRegressions;
  for (const auto& dir : fs::directory_iterator(kRegressions)) {
    if (!dir.is_directory()) continue;
    EXPECT_EQ(targets.count(dir.path().filename().string()), 1u)
        << dir.path() << " is not a fuzz target (fuzz_entries.cc AllEntries)";
  }
}

// Peak resident memory of this process so far (MiB).
long PeakRssMb() {
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  return usage.ru_maxrss / 1024;
}

// Several inputs once made a parser allocate gigabytes on the word of a header (out-of-memory
// under the fuzzer's 2 GB limit): replaying one may not raise the peak by more than this.
constexpr long kMaxGrowthMb = 512;

TEST(FuzzRegressionsTest, EveryInputIsACleanErrorOrConsistent) {
  std::size_t replayed = 0;
  const long baseline_mb = PeakRssMb();
  for (const NamedEntry& e : AllEntries()) {
    const fs::path dir = kRegressions / e.target;
    if (!fs::is_directory(dir)) continue;
    for (const auto& file : fs::directory_iterator(dir)) {
      if (!file.is_regular_file() || file.path().extension() == ".md") continue;
      const std::string bytes = Slurp(file.path());
      const Outcome o = e.entry(reinterpret_cast<const std::uint8_t*>(bytes.data()), bytes.size());
      EXPECT_NE(o.verdict, Verdict::kBroken) << file.path() << ": " << o.message;
      if (o.verdict == Verdict::kRejected) {
        EXPECT_FALSE(o.message.empty()) << file.path();
      }
      EXPECT_LT(PeakRssMb() - baseline_mb, kMaxGrowthMb) << file.path() << " took memory";
      ++replayed;
    }
  }
  EXPECT_GT(replayed, 0u) << "no inputs under " << kRegressions;
}

Outcome Replay(Entry entry, const std::string& bytes) {
  return entry(reinterpret_cast<const std::uint8_t*>(bytes.data()), bytes.size());
}

// Too large for a file under regressions/: a .ot whose header ends, for OctoMap's token-based
// parser, on the "res" line, with a 200 k-node chain (each node the only child of the one
// before) in the comment line that follows. LoadSnapshotFile checked the nodes after its own
// "data" line, and OctoMap then recursed down the chain until the stack ran out.
TEST(FuzzRegressionsTest, SnapshotHeaderEndingEarlyForOctoMapIsNotABypass) {
  const auto node = [](std::uint8_t children) {
    const float log_odds = 0.5f;
    std::string bytes(reinterpret_cast<const char*>(&log_odds), sizeof log_odds);
    return bytes + static_cast<char>(children);
  };
  std::string chain;
  for (int k = 0; k < 200'000; ++k) chain += node(k + 1 < 200'000 ? 1 : 0);
  ASSERT_EQ(chain.find('\n'), std::string::npos);
  const std::string file =
      "# Octomap OcTree file\nid OcTree\nsize 1\nres 0.05 data\n#" + chain + "\ndata\n" + node(0);
  const Outcome o = Replay(RunSnapshot, file);
  EXPECT_EQ(o.verdict, Verdict::kAccepted) << o.message;  // the one node after "data"
}

// An empty map (OcTree::write with no root: "size 0", no node data) is what fusiond saves when
// it stops before any cloud arrived; it was set aside as corrupt at the next start.
TEST(FuzzRegressionsTest, EmptyMapSnapshotLoads) {
  std::ostringstream empty;
  octomap::OcTree(0.05).write(empty);
  const Outcome o = Replay(RunSnapshot, empty.str());
  EXPECT_EQ(o.verdict, Verdict::kAccepted) << o.message;
}

}  // namespace
}  // namespace fusion::fuzz
