// The fixture and helpers of the WorldMap tests (world_map_test.cc: input, periods, fusion;
// world_map_publication_test.cc: what the publications carry, coarse free space, saturation;
// world_map_forgetting_test.cc: the history's clamp, forgetting with a half-life):
// an SR-3000 at 44 x 36 beams before the paper's board, 4 cm voxels.
#pragma once

#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include "fusion/core/fusion_rules.h"
#include "fusion/core/octree_merge.h"
#include "fusion/core/projective_render.h"
#include "fusion/core/world_map.h"
#include "fusion/sim/scene.h"
#include "fusion/sim/simulator.h"

namespace fusion {

inline constexpr double kRes = 0.04;

struct Leaf {
  octomap::OcTreeKey key;
  unsigned depth;
  float log_odds;
};

// Leaves in iteration order (depth first), coarse ones with their depth.
inline std::vector<Leaf> Leaves(const octomap::OcTree& tree) {
  std::vector<Leaf> leaves;
  for (auto it = tree.begin_leafs(); it != tree.end_leafs(); ++it) {
    leaves.push_back({it.getKey(), it.getDepth(), it->getLogOdds()});
  }
  return leaves;
}

inline void ExpectSameLeaves(const octomap::OcTree& a, const octomap::OcTree& b) {
  const auto la = Leaves(a);
  const auto lb = Leaves(b);
  ASSERT_EQ(la.size(), lb.size());
  for (std::size_t i = 0; i < la.size(); ++i) {
    ASSERT_EQ(la[i].key, lb[i].key) << i;
    ASSERT_EQ(la[i].depth, lb[i].depth) << i;
    ASSERT_EQ(la[i].log_odds, lb[i].log_odds) << i;
  }
}

// A sensor's opinion as the map renders it.
inline RenderedGrid Opinion(const WorldMap& map, const std::string& id, const Eigen::Isometry3d& T) {
  return Render(*map.beam_grid(id), T, MapRenderOptions(map.options()));
}

// A client of the change log: applies each publication's regions, as StreamUpdates sends them
// (ForEachInRegion: the region's leaves, or the region with one value, or nothing), to its own
// tree.
class Follower {
 public:
  explicit Follower(double resolution_m) : tree_(resolution_m) {}
  void Apply(const Publication& p) {
    if (p.changes.reset) {
      tree_.clear();
      leaves_ = 0;
    }
    const std::vector<MapRegion> all{{0, 0}};
    RenderedGrid values(tree_.getResolution()), removed(tree_.getResolution());
    for (const MapRegion& region : p.changes.reset ? all : p.changes.regions) {
      ForEachInRegion(
          *p.tree, region,
          [&](const octomap::OcTreeKey& key, unsigned depth, const octomap::OcTreeNode* node) {
            const MapNode n{MortonAtDepth(MortonOf(key), depth), node ? node->getLogOdds() : 0.0f,
                            static_cast<std::uint8_t>(depth)};
            (node ? values : removed).Append(n);
          });
    }
    // One value per piece (a copy): the policy's clamping is the map's own.
    std::int64_t added = 0;
    FuseRegions(tree_, FusionPolicy{}, {{nullptr, &values}}, {&values, &removed}, nullptr,
                nullptr, &added);
    leaves_ = static_cast<std::size_t>(static_cast<std::int64_t>(leaves_) + added);
    // The leaf counts kept without walking: the map's of its version, the follower's own.
    EXPECT_EQ(p.leaves, p.tree->getNumLeafNodes()) << "version " << p.changes.version;
    EXPECT_EQ(leaves_, tree_.getNumLeafNodes()) << "version " << p.changes.version;
  }
  const octomap::OcTree& tree() const { return tree_; }

 private:
  octomap::OcTree tree_;
  std::size_t leaves_ = 0;
};

class WorldMapTest : public ::testing::Test {
 protected:
  WorldMapTest()
      : spec_(sim::WithTessellation(*SensorPreset("sr3000"), 44, 36)),
        simulator_(sim::PaperBoardScene(), spec_, sim::SimOptions{}),
        pose_(sim::ForwardLookingPose(Eigen::Vector3d::Zero())) {
    options_.resolution_m = kRes;
  }
  sim::OrganizedCloud Frame() { return simulator_.Capture(pose_); }
  static MapStatus Add(WorldMap* map, const std::string& id, const Eigen::Isometry3d& T,
                       const sim::OrganizedCloud& c, bool* committed = nullptr) {
    return map->Integrate(id, T, c.xyz.data(), c.size(), c.beyond_range, nullptr, committed);
  }

  void ExpectNothingOutsideTheMap();

  SensorSpec spec_;
  sim::RangeSimulator simulator_;
  Eigen::Isometry3d pose_;
  WorldMapOptions options_;
};

}  // namespace fusion
