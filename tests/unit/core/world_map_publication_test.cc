// What WorldMap's publications carry (a follower of them reproduces the map), coarse free
// nodes, and leaving out saturated free space.
#include "fusion/core/world_map.h"

#include "world_map_fixture.h"

namespace fusion {
namespace {

TEST_F(WorldMapTest, AFollowerOfThePublicationsReproducesTheMapExactly) {
  WorldMap map(options_);
  ASSERT_EQ(map.AddSensor("sr", spec_), MapStatus::kOk);
  Follower follower(kRes);
  std::uint64_t last = 0;
  const auto follow = [&] {
    const Publication p = map.Publish();
    if (p.changes.version == last) return;
    ASSERT_EQ(p.changes.version, last + 1) << "every version is seen";
    last = p.changes.version;
    follower.Apply(p);
    ExpectSameLeaves(*p.tree, follower.tree());
  };
  // A stationary period re-rendered, then a moving sensor (a commit per pose), then a reset.
  for (int i = 0; i < 3; ++i) {
    ASSERT_EQ(Add(&map, "sr", pose_, Frame()), MapStatus::kOk);
    ASSERT_EQ(map.Render("sr"), MapStatus::kOk);
    ASSERT_NO_FATAL_FAILURE(follow());
  }
  for (int k = 1; k <= 4; ++k) {
    Eigen::Isometry3d moved = pose_;
    moved.translation() += Eigen::Vector3d(0.1 * k, 0.05 * k, 0.0);
    ASSERT_EQ(Add(&map, "sr", moved, simulator_.Capture(moved)), MapStatus::kOk);
    ASSERT_NO_FATAL_FAILURE(follow());
    ASSERT_EQ(map.Render("sr"), MapStatus::kOk);
    ASSERT_NO_FATAL_FAILURE(follow());
  }
  std::size_t coarse = 0;
  for (auto it = follower.tree().begin_leafs(); it != follower.tree().end_leafs(); ++it) {
    coarse += it.getDepth() < 16 ? 1 : 0;
  }
  EXPECT_GT(coarse, 100u) << "coarse nodes travel through the log";
  map.Reset();
  ASSERT_EQ(Add(&map, "sr", pose_, Frame()), MapStatus::kOk);
  ASSERT_EQ(map.Render("sr"), MapStatus::kOk);
  ASSERT_NO_FATAL_FAILURE(follow());
  // A snapshot loaded as the history (a reset), then a sensor over it.
  const octomap::OcTree loaded(follower.tree());
  map.LoadHistory(loaded);
  ASSERT_NO_FATAL_FAILURE(follow());
  Eigen::Isometry3d moved = pose_;
  moved.translation() += Eigen::Vector3d(0.3, 0.0, 0.0);
  ASSERT_EQ(Add(&map, "sr", moved, simulator_.Capture(moved)), MapStatus::kOk);
  ASSERT_EQ(map.Render("sr"), MapStatus::kOk);
  ASSERT_NO_FATAL_FAILURE(follow());
}

// ClearBox forgets exactly the voxels whose centres lie in the box (the live contribution
// folded in first), leaves every other voxel as it was, and its publication lets a follower
// reproduce the map.
TEST_F(WorldMapTest, ClearBoxForgetsTheBoxAndNothingElse) {
  WorldMap map(options_);
  ASSERT_EQ(map.AddSensor("sr", spec_), MapStatus::kOk);
  Follower follower(kRes);
  std::uint64_t last = 0;
  const auto follow = [&] {  // every version, in turn
    const Publication p = map.Publish();
    if (p.changes.version == last) return;
    ASSERT_EQ(p.changes.version, last + 1);
    last = p.changes.version;
    follower.Apply(p);
  };
  ASSERT_EQ(Add(&map, "sr", pose_, Frame()), MapStatus::kOk);
  ASSERT_EQ(map.Commit("sr"), MapStatus::kOk);  // history
  ASSERT_NO_FATAL_FAILURE(follow());
  ASSERT_EQ(Add(&map, "sr", pose_, Frame()), MapStatus::kOk);
  ASSERT_EQ(map.Render("sr"), MapStatus::kOk);  // and a live contribution
  ASSERT_NO_FATAL_FAILURE(follow());
  ASSERT_GT(map.Counters("sr")->live_nodes, 0u);

  octomap::OcTree before(map.tree());
  before.expand();  // every voxel a leaf
  const Eigen::AlignedBox3d box(Eigen::Vector3d(1.0, -0.3, -0.25), Eigen::Vector3d(2.0, 0.3, 0.35));
  std::uint64_t in_box = 0, occupied_in_box = 0;
  for (auto it = before.begin_leafs(); it != before.end_leafs(); ++it) {
    if (!box.contains(Eigen::Vector3d(it.getX(), it.getY(), it.getZ()))) continue;
    ++in_box;
    occupied_in_box += before.isNodeOccupied(*it) ? 1 : 0;
  }
  ASSERT_GT(occupied_in_box, 50u) << "the box holds part of the board";

  EXPECT_EQ(map.ClearBox(box), in_box);
  EXPECT_EQ(map.Counters("sr")->live_nodes, 0u) << "folded into the history";
  EXPECT_EQ(map.Counters("sr")->frames_in_period, 0u) << "the period restarted";
  const octomap::OcTree& after = map.tree();
  for (auto it = before.begin_leafs(); it != before.end_leafs(); ++it) {
    const octomap::OcTreeNode* node = after.search(it.getKey());
    if (box.contains(Eigen::Vector3d(it.getX(), it.getY(), it.getZ()))) {
      ASSERT_EQ(node, nullptr) << "a voxel in the box is still known";
    } else {
      ASSERT_NE(node, nullptr) << "a voxel outside the box was forgotten";
      ASSERT_EQ(node->getLogOdds(), it->getLogOdds());
    }
  }
  const Publication p = map.Publish();
  EXPECT_EQ(p.changes.version, last + 1);
  EXPECT_FALSE(p.changes.regions.empty());
  ASSERT_NO_FATAL_FAILURE(follow());
  ExpectSameLeaves(*p.tree, follower.tree());
  EXPECT_EQ(map.ClearBox(box), 0u) << "nothing left to forget";
  // The history was cleared too, and the period restarted: the next commit brings nothing back.
  ASSERT_EQ(map.Commit("sr"), MapStatus::kOk);
  EXPECT_EQ(map.Occupancy(Eigen::Vector3d(1.5, 0.0, 0.05)), std::nullopt);
}

TEST_F(WorldMapTest, CoarseFreeNodesAnswerFreeAndSplitForANewSurface) {
  WorldMap map(options_);
  ASSERT_EQ(map.AddSensor("sr", spec_), MapStatus::kOk);
  ASSERT_EQ(Add(&map, "sr", pose_, Frame()), MapStatus::kOk);
  ASSERT_EQ(map.Render("sr"), MapStatus::kOk);
  // A coarse free leaf in front of the board, and points anywhere inside it.
  const octomap::OcTree& tree = map.tree();
  octomap::OcTreeKey block_key;
  unsigned block_depth = 16;
  double block_size = 0.0;
  for (auto it = tree.begin_leafs(); it != tree.end_leafs(); ++it) {
    if (it.getDepth() <= 13 && it->getOccupancy() < 0.1 && it.getX() > 0.9 && it.getX() < 1.4) {
      block_key = it.getKey();
      block_depth = it.getDepth();
      block_size = it.getSize();
      break;
    }
  }
  ASSERT_LT(block_depth, 16u) << "free space in front of the board is held in coarse leaves";
  const octomap::point3d centre = tree.keyToCoord(block_key, block_depth);
  const Eigen::Vector3d c(centre.x(), centre.y(), centre.z());
  for (int i = 0; i < 50; ++i) {
    const Eigen::Vector3d offset =
        (Eigen::Vector3d::Random() * 0.499 * block_size).cwiseMin(0.49 * block_size);
    const auto p = map.Occupancy(c + offset);
    ASSERT_TRUE(p.has_value());
    EXPECT_LT(*p, 0.1);
  }
  // A second sensor sees a wall inside that block: the block splits, the wall is occupied there
  // and the rest of the block stays free.
  Eigen::Isometry3d close = pose_;
  close.translation() = c - Eigen::Vector3d(0.9, 0.0, 0.0);
  std::string error;
  const auto wall =
      sim::ParseScene("rect wall " + std::to_string(c.x()) + " " + std::to_string(c.y()) + " " +
                          std::to_string(c.z()) + "  0 1 0  0 0 1  0.3 0.3\n",
                      &error);
  ASSERT_TRUE(wall.has_value()) << error;
  ASSERT_EQ(map.AddSensor("second", spec_), MapStatus::kOk);
  sim::RangeSimulator second(*wall, spec_, sim::SimOptions{});
  for (int i = 0; i < 5; ++i) {
    const auto cloud = second.Capture(close);
    ASSERT_EQ(map.Integrate("second", close, cloud.xyz.data(), cloud.size(), cloud.beyond_range),
              MapStatus::kOk);
  }
  ASSERT_EQ(map.Render("second"), MapStatus::kOk);
  const auto on_wall = map.Occupancy(c + Eigen::Vector3d(0.001, 0.011, 0.011));
  ASSERT_TRUE(on_wall.has_value());
  EXPECT_GT(*on_wall, 0.5) << "the wall inside the old free block";
  const octomap::OcTreeNode* node = map.tree().search(block_key, block_depth);
  ASSERT_NE(node, nullptr);
  EXPECT_TRUE(map.tree().nodeHasChildren(node)) << "the block was split";
  const auto corner = map.Occupancy(c + Eigen::Vector3d(-0.45, -0.45, -0.45) * block_size);
  ASSERT_TRUE(corner.has_value());
  EXPECT_LT(*corner, 0.1) << "the rest of the block stays free";
}

// Leaving out free space the history holds at the free clamp changes nothing (Eq. 16): a
// moving sensor mapped with the facade (which passes WorldMap::Saturation to every render)
// gives exactly the map rendered without it.
// The same with the renders on two threads (the octree's blocks shared out, each thread
// checking the history and the live contributions on its own).
TEST_F(WorldMapTest, LeavingOutSaturatedFreeSpaceGivesTheSameMap) {
  WorldMapOptions threaded_options = options_;
  threaded_options.render.threads = 2;
  WorldMap with(options_), without(options_), threaded(threaded_options);
  ASSERT_EQ(with.AddSensor("sr", spec_), MapStatus::kOk);
  ASSERT_EQ(without.AddSensor("sr", spec_), MapStatus::kOk);
  ASSERT_EQ(threaded.AddSensor("sr", spec_), MapStatus::kOk);
  SensorPeriods periods(spec_, SensorGridOptions(options_), options_.pose_tolerance_m,
                        options_.pose_tolerance_rad);
  std::size_t skipped = 0;
  for (int k = 0; k < 8; ++k) {
    Eigen::Isometry3d T = pose_;
    T.translation() += Eigen::Vector3d(0.03 * k, 0.04 * (k % 3), 0.0);
    const auto cloud = simulator_.Capture(T);
    ASSERT_EQ(Add(&with, "sr", T, cloud), MapStatus::kOk);
    FuseStats stats;
    ASSERT_EQ(with.Render("sr", &stats), MapStatus::kOk);
    skipped += stats.render.skipped_saturated;
    ASSERT_EQ(Add(&threaded, "sr", T, cloud), MapStatus::kOk);
    FuseStats threaded_stats;
    ASSERT_EQ(threaded.Render("sr", &threaded_stats), MapStatus::kOk);
    EXPECT_EQ(threaded_stats.render.skipped_saturated, stats.render.skipped_saturated);
    ExpectSameLeaves(with.tree(), threaded.tree());
    // The same frame by hand, one period per frame, rendered without the hint.
    std::unique_ptr<Period> sealed;
    PeriodIntegration result;
    ASSERT_EQ(periods.Integrate(T, cloud.xyz.data(), cloud.size(), cloud.beyond_range, true,
                                &result, &sealed),
              MapStatus::kOk);
    if (sealed) {
      ASSERT_EQ(without.CommitLive("sr"), MapStatus::kOk);
    }
    const Period& open = periods.open();
    ASSERT_EQ(without.ReplaceLive("sr", Render(*open.grid, open.T_world_sensor,
                                               MapRenderOptions(options_))),
              MapStatus::kOk);
    ExpectSameLeaves(without.tree(), with.tree());
  }
  EXPECT_GT(skipped, 100u) << "the frames after the first leave saturated space out";
}

}  // namespace
}  // namespace fusion
