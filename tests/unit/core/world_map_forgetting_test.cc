// The committed history of a world that changes: its tighter occupied clamp
// (WorldMapOptions::history_clamping_max_probability) and forgetting with a half-life
// (forget_half_life_s, WorldMap::Forget).
#include <cmath>

#include "fusion/core/world_map.h"
#include "world_map_fixture.h"

namespace fusion {
namespace {

float MaxLogOdds(const octomap::OcTree& tree) {
  float max = -100.0f;
  for (const Leaf& leaf : Leaves(tree)) max = std::max(max, leaf.log_odds);
  return max;
}

// A period's own certainty is the fused map's (0.999) while it is live; committed, it is held
// at the history's clamp, and the map shows exactly what the history holds: the reference map
// (default clamps) with its values cut at the history's clamp.
TEST_F(WorldMapTest, TheHistorysClampBoundsWhatIsCommittedNotWhatIsLive) {
  WorldMapOptions tight = options_;
  tight.history_clamping_max_probability = 0.9;
  const float clamp = static_cast<float>(LogOdds(0.9));
  WorldMap map(tight), reference(options_);
  for (WorldMap* m : {&map, &reference}) ASSERT_EQ(m->AddSensor("sr", spec_), MapStatus::kOk);
  for (int k = 0; k < 10; ++k) {
    const sim::OrganizedCloud cloud = Frame();
    ASSERT_EQ(Add(&map, "sr", pose_, cloud), MapStatus::kOk);
    ASSERT_EQ(Add(&reference, "sr", pose_, cloud), MapStatus::kOk);
  }
  ASSERT_EQ(map.Render("sr"), MapStatus::kOk);
  EXPECT_GT(MaxLogOdds(map.tree()), clamp + 2.0f) << "live: the period's own certainty";
  ASSERT_EQ(map.Commit("sr"), MapStatus::kOk);
  ASSERT_EQ(reference.Commit("sr"), MapStatus::kOk);
  EXPECT_LE(MaxLogOdds(map.tree()), clamp + 1e-5f) << "committed: the history's clamp";
  std::size_t cut = 0;
  for (const Leaf& leaf : Leaves(reference.tree())) {
    const octomap::OcTreeNode* node = map.tree().search(leaf.key, leaf.depth);
    ASSERT_NE(node, nullptr);
    ASSERT_NEAR(node->getLogOdds(), std::min(leaf.log_odds, clamp), 1e-5);
    cut += leaf.log_odds > clamp ? 1 : 0;
  }
  EXPECT_GT(cut, 50u) << "the board's voxels were cut";
  WorldMapOptions bad = options_;
  bad.history_clamping_max_probability = 0.9999;
  std::string why;
  EXPECT_FALSE(bad.IsValid(&why));
  EXPECT_EQ(why.rfind("history_clamping_max_probability", 0), 0u) << why;
}

// Forget halves the history's log-odds per half-life, removes what comes near 0, leaves the
// live contribution alone, and its publication lets a follower reproduce the map.
TEST_F(WorldMapTest, ForgettingDecaysTheHistoryTowardUnknown) {
  WorldMapOptions forgetting = options_;
  forgetting.forget_half_life_s = 2.0;
  WorldMap map(forgetting);
  ASSERT_EQ(map.AddSensor("sr", spec_), MapStatus::kOk);
  Follower follower(kRes);
  for (int k = 0; k < 5; ++k) ASSERT_EQ(Add(&map, "sr", pose_, Frame()), MapStatus::kOk);
  ASSERT_EQ(map.Render("sr"), MapStatus::kOk);  // each publication in turn to the follower
  follower.Apply(map.Publish());
  ASSERT_EQ(map.Commit("sr"), MapStatus::kOk);
  follower.Apply(map.Publish());
  const std::vector<Leaf> before = Leaves(map.tree());
  ASSERT_GT(before.size(), 100u);

  EXPECT_EQ(map.Forget(0.0), 0u);
  map.Forget(2.0);  // one half-life
  for (const Leaf& leaf : before) {
    const octomap::OcTreeNode* node = map.tree().search(leaf.key, leaf.depth);
    if (std::abs(leaf.log_odds) * 0.5f < WorldMapOptions::kForgottenLogOdds) {
      EXPECT_EQ(node, nullptr);
      continue;
    }
    ASSERT_NE(node, nullptr);
    ASSERT_NEAR(node->getLogOdds(), 0.5f * leaf.log_odds, 1e-5f);
  }
  const Publication decayed = map.Publish();
  follower.Apply(decayed);
  ExpectSameLeaves(follower.tree(), *decayed.tree);

  // What the sensor sees now stays; everything committed before is forgotten.
  ASSERT_EQ(Add(&map, "sr", pose_, Frame()), MapStatus::kOk);
  ASSERT_EQ(map.Render("sr"), MapStatus::kOk);
  follower.Apply(map.Publish());
  EXPECT_GT(map.Forget(1000.0), 0u);
  WorldMap fresh(forgetting);
  ASSERT_EQ(fresh.AddSensor("sr", spec_), MapStatus::kOk);
  ASSERT_EQ(fresh.ReplaceLive("sr", Opinion(map, "sr", pose_)), MapStatus::kOk);
  ExpectSameLeaves(map.tree(), fresh.tree());
  follower.Apply(map.Publish());
  ExpectSameLeaves(follower.tree(), map.tree());
}

TEST_F(WorldMapTest, ForgettingIsOffByDefault) {
  EXPECT_EQ(WorldMapOptions{}.forget_half_life_s, 0.0);
  WorldMap map(options_);
  ASSERT_EQ(map.AddSensor("sr", spec_), MapStatus::kOk);
  ASSERT_EQ(Add(&map, "sr", pose_, Frame()), MapStatus::kOk);
  ASSERT_EQ(map.Commit("sr"), MapStatus::kOk);
  const std::uint64_t version = map.Publish().changes.version;
  const octomap::OcTree before(map.tree());
  EXPECT_EQ(map.Forget(1000.0), 0u);
  ExpectSameLeaves(map.tree(), before);
  EXPECT_EQ(map.Publish().changes.version, version);
  WorldMapOptions bad = options_;
  bad.forget_half_life_s = -1.0;
  EXPECT_FALSE(bad.IsValid());
}

}  // namespace
}  // namespace fusion
