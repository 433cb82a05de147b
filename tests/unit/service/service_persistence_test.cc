// Snapshot files: atomic write, load, truncated / garbage files set aside, resolution checked.
#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <vector>

#include <filesystem>
#include <fstream>
#include <string>

#include "fusion/service/persistence.h"

namespace fusion::service {
namespace {

namespace fs = std::filesystem;

class ServicePersistenceTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = ::testing::TempDir() + "service_persistence_" +
           ::testing::UnitTest::GetInstance()->current_test_info()->name();
    fs::remove_all(dir_);
    fs::create_directories(dir_);
    path_ = dir_ + "/map.ot";
    tree_.updateNode(octomap::point3d(1.0f, 0.0f, 0.0f), true);
    tree_.updateNode(octomap::point3d(0.5f, 0.0f, 0.0f), false);
  }
  int CountCorrupt() const {
    int n = 0;
    for (const auto& e : fs::directory_iterator(dir_)) {
      n += e.path().filename().string().rfind("map.ot.corrupt-", 0) == 0;
    }
    return n;
  }
  std::string dir_, path_;
  octomap::OcTree tree_{0.05};
};

TEST_F(ServicePersistenceTest, WritesAtomicallyAndLoadsBack) {
  std::uint64_t bytes = 0;
  const fusion::Status written = WriteSnapshotFile(tree_, path_, &bytes);
  ASSERT_TRUE(written.ok()) << written.message();
  std::string error;
  EXPECT_EQ(bytes, fs::file_size(path_));
  for (const auto& e : fs::directory_iterator(dir_)) {
    EXPECT_EQ(e.path().filename(), "map.ot") << "temporary file left behind";
  }
  std::unique_ptr<octomap::OcTree> loaded;
  ASSERT_EQ(LoadSnapshotFile(path_, 0.05, &loaded, &error), LoadStatus::kLoaded) << error;
  EXPECT_EQ(loaded->size(), tree_.size());
  EXPECT_TRUE(loaded->isNodeOccupied(loaded->search(1.0, 0.0, 0.0)));
  EXPECT_FALSE(loaded->isNodeOccupied(loaded->search(0.5, 0.0, 0.0)));
  // The layout the truncation check relies on: 5 bytes per node after the header.
  const std::string data = SerializeOt(tree_);
  const auto start = data.find("\ndata\n");
  ASSERT_NE(start, std::string::npos);
  EXPECT_EQ(data.size() - (start + 6), 5 * tree_.size());
}

TEST_F(ServicePersistenceTest, MissingFileIsNotAnError) {
  std::unique_ptr<octomap::OcTree> loaded;
  std::string error;
  EXPECT_EQ(LoadSnapshotFile(path_, 0.05, &loaded, &error), LoadStatus::kMissing);
}

TEST_F(ServicePersistenceTest, TruncatedAndGarbageFilesAreSetAside) {
  const std::string data = SerializeOt(tree_);
  for (const std::string& bad :
       {data.substr(0, data.size() - 3), std::string("garbage\n"), data + "extra"}) {
    std::ofstream(path_, std::ios::binary) << bad;
    std::unique_ptr<octomap::OcTree> loaded;
    std::string message;
    const int before = CountCorrupt();
    EXPECT_EQ(LoadSnapshotFile(path_, 0.05, &loaded, &message), LoadStatus::kCorrupt);
    EXPECT_EQ(loaded, nullptr);
    EXPECT_NE(message.find("moved to"), std::string::npos) << message;
    EXPECT_FALSE(fs::exists(path_));
    // Same-second names collide: the test renames the set-aside file to keep each one.
    for (const auto& e : fs::directory_iterator(dir_)) {
      if (e.path().filename().string().rfind("map.ot.corrupt-", 0) == 0 &&
          e.path().filename().string().find("-kept") == std::string::npos) {
        fs::rename(e.path(), e.path().string() + "-kept" + std::to_string(before));
      }
    }
    EXPECT_EQ(CountCorrupt(), before + 1);
  }
}

// A .ot of `nodes` nodes (values `log_odds`), each node's flags from `flags(k)`.
std::string CraftedOt(std::uint64_t nodes, const std::function<std::uint8_t(std::uint64_t)>& flags,
                      float log_odds = 0.5f) {
  std::string out = "# Octomap OcTree file\nid OcTree\nsize " + std::to_string(nodes) +
                    "\nres 0.05\ndata\n";
  for (std::uint64_t k = 0; k < nodes; ++k) {
    out.append(reinterpret_cast<const char*>(&log_odds), sizeof log_odds);
    out.push_back(static_cast<char>(flags(k)));
  }
  return out;
}

// Once a crash loop: OctoMap's reader recursed down a crafted chain until the stack ran out.
TEST_F(ServicePersistenceTest, CraftedStructuresAreSetAsideNotLoaded) {
  const std::vector<std::pair<std::string, std::string>> cases = {
      // 200 k nodes, each the only child of the one before: consistent counts, 200 k levels.
      {CraftedOt(200'000, [](std::uint64_t k) { return k + 1 < 200'000 ? 1 : 0; }), "deeper"},
      // 17 levels: one more than OctoMap's depth.
      {CraftedOt(18, [](std::uint64_t k) { return k + 1 < 18 ? 0x80 : 0; }), "deeper"},
      // Flags asking for more children than the header's nodes.
      {CraftedOt(3, [](std::uint64_t) { return 0xff; }), "more than"},
      // Fewer nodes in the tree than the header declares (the rest is trailing garbage).
      {CraftedOt(5, [](std::uint64_t k) { return k == 0 ? 1 : 0; }), "holds 2"},
      {CraftedOt(1, [](std::uint64_t) { return 0; }, std::nanf("")), "not finite"},
  };
  for (const auto& [bytes, why] : cases) {
    std::ofstream(path_, std::ios::binary) << bytes;
    std::unique_ptr<octomap::OcTree> loaded;
    std::string message;
    EXPECT_EQ(LoadSnapshotFile(path_, 0.05, &loaded, &message), LoadStatus::kCorrupt) << why;
    EXPECT_EQ(loaded, nullptr);
    EXPECT_NE(message.find(why), std::string::npos) << message;
    EXPECT_FALSE(fs::exists(path_)) << "set aside";
  }
  // A legitimate deep tree (one voxel at depth 16) still loads.
  octomap::OcTree one(0.05);
  one.updateNode(octomap::point3d(1.0f, 2.0f, 3.0f), true);
  const fusion::Status written = WriteSnapshotFile(one, path_, nullptr);
  ASSERT_TRUE(written.ok()) << written.message();
  std::string error;
  std::unique_ptr<octomap::OcTree> loaded;
  ASSERT_EQ(LoadSnapshotFile(path_, 0.05, &loaded, &error), LoadStatus::kLoaded) << error;
  EXPECT_EQ(loaded->size(), one.size());
}

TEST_F(ServicePersistenceTest, OtherResolutionIsRefusedNotSetAside) {
  const fusion::Status written = WriteSnapshotFile(tree_, path_, nullptr);
  ASSERT_TRUE(written.ok()) << written.message();
  std::string error;
  std::unique_ptr<octomap::OcTree> loaded;
  EXPECT_EQ(LoadSnapshotFile(path_, 0.1, &loaded, &error), LoadStatus::kError);
  EXPECT_NE(error.find("resolution"), std::string::npos) << error;
  EXPECT_TRUE(fs::exists(path_));
}

TEST_F(ServicePersistenceTest, UnwritableDirectoryIsReported) {
  const fusion::Status written = WriteSnapshotFile(tree_, dir_ + "/no/such/dir/map.ot", nullptr);
  EXPECT_FALSE(written.ok());
  EXPECT_NE(written.message().find("open"), std::string::npos) << written.message();
}

}  // namespace
}  // namespace fusion::service
