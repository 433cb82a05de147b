#include "fusion/core/octree_merge.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <functional>
#include <map>
#include <random>
#include <tuple>
#include <vector>

namespace fusion {
namespace {

using KeyTuple = std::tuple<int, int, int>;

octomap::OcTreeKey Key(const KeyTuple& t) {
  return octomap::OcTreeKey(static_cast<octomap::key_type>(std::get<0>(t)),
                            static_cast<octomap::key_type>(std::get<1>(t)),
                            static_cast<octomap::key_type>(std::get<2>(t)));
}

// The oracle: a tree built from scratch from the voxels that remain.
void ExpectSameVoxels(const octomap::OcTree& tree, const std::map<KeyTuple, float>& voxels,
                      const std::vector<KeyTuple>& deleted) {
  octomap::OcTree oracle(tree.getResolution());
  for (const auto& [k, v] : voxels) oracle.setNodeValue(Key(k), v);
  for (const auto& [k, v] : voxels) {
    const octomap::OcTreeNode* node = tree.search(Key(k));
    ASSERT_NE(node, nullptr);
    EXPECT_FLOAT_EQ(node->getLogOdds(), v);
  }
  for (const auto& k : deleted) {
    if (voxels.count(k) == 0) {
      EXPECT_EQ(tree.search(Key(k)), nullptr);
    }
  }
  // Inner values are the max of their children, as in the oracle; no node is left over.
  ASSERT_EQ(tree.getRoot() == nullptr, oracle.getRoot() == nullptr);
  if (oracle.getRoot() != nullptr) {
    EXPECT_FLOAT_EQ(tree.getRoot()->getLogOdds(), oracle.getRoot()->getLogOdds());
  }
  octomap::OcTree expanded_tree(tree), expanded_oracle(oracle);
  expanded_tree.expand();
  expanded_oracle.expand();
  EXPECT_EQ(expanded_tree.size(), expanded_oracle.size());
  EXPECT_EQ(expanded_tree.getNumLeafNodes(), expanded_oracle.getNumLeafNodes());
}

TEST(DeleteVoxel, MatchesATreeBuiltWithoutTheDeletedVoxels) {
  std::mt19937 rng(5);
  std::uniform_int_distribution<int> coord(32760, 32775);
  // Few distinct values, so that OctoMap prunes whole blocks of equal siblings.
  const float values[] = {-2.0f, 0.85f, 3.5f};
  std::uniform_int_distribution<int> pick(0, 2);
  octomap::OcTree tree(0.05);
  std::map<KeyTuple, float> voxels;
  for (int i = 0; i < 3000; ++i) {
    const KeyTuple k{coord(rng), coord(rng), coord(rng)};
    const float v = values[pick(rng)];
    voxels[k] = v;
    tree.setNodeValue(Key(k), v);
  }
  // A fully equal 2x2x2 block: pruned into one node, then one of its voxels deleted.
  for (int dx = 0; dx < 2; ++dx)
    for (int dy = 0; dy < 2; ++dy)
      for (int dz = 0; dz < 2; ++dz) {
        const KeyTuple k{32800 + dx, 32800 + dy, 32800 + dz};
        voxels[k] = 1.0f;
        tree.setNodeValue(Key(k), 1.0f);
      }
  ASSERT_NE(tree.search(Key({32800, 32800, 32800})), nullptr);
  std::vector<KeyTuple> deleted{{32800, 32801, 32800}};
  std::vector<KeyTuple> all;
  for (const auto& [k, v] : voxels) all.push_back(k);
  std::shuffle(all.begin(), all.end(), rng);
  deleted.insert(deleted.end(), all.begin(), all.begin() + 1200);
  for (const auto& k : deleted) {
    EXPECT_TRUE(DeleteVoxel(tree, Key(k)));
    voxels.erase(k);
  }
  ExpectSameVoxels(tree, voxels, deleted);
}

TEST(DeleteVoxel, AbsentKeysLeaveTheTreeAlone) {
  octomap::OcTree tree(0.05);
  EXPECT_FALSE(DeleteVoxel(tree, Key({100, 100, 100})));  // empty tree
  tree.setNodeValue(Key({100, 100, 100}), 2.0f);
  const std::size_t size = tree.size();
  EXPECT_FALSE(DeleteVoxel(tree, Key({100, 100, 101})));
  EXPECT_FALSE(DeleteVoxel(tree, Key({40000, 100, 100})));
  EXPECT_EQ(tree.size(), size);
  ASSERT_NE(tree.search(Key({100, 100, 100})), nullptr);
}

TEST(DeleteVoxel, DeletingTheLastVoxelEmptiesTheTree) {
  octomap::OcTree tree(0.05);
  tree.setNodeValue(Key({100, 100, 100}), 2.0f);
  tree.setNodeValue(Key({30000, 100, 100}), -1.0f);
  EXPECT_TRUE(DeleteVoxel(tree, Key({100, 100, 100})));
  EXPECT_EQ(tree.search(Key({100, 100, 100})), nullptr);
  ASSERT_NE(tree.search(Key({30000, 100, 100})), nullptr);
  EXPECT_FLOAT_EQ(tree.getRoot()->getLogOdds(), -1.0f);
  EXPECT_TRUE(DeleteVoxel(tree, Key({30000, 100, 100})));
  EXPECT_EQ(tree.getRoot(), nullptr);
  EXPECT_EQ(tree.size(), 0u);
  // The emptied tree takes new voxels.
  tree.setNodeValue(Key({5, 5, 5}), 1.0f);
  EXPECT_NE(tree.search(Key({5, 5, 5})), nullptr);
}

}  // namespace
}  // namespace fusion

namespace fusion {
namespace {

// Voxels of a small cube of the key space, each with an optional value: the oracle of merges.
constexpr int kBase = 32768 - 16;
constexpr int kSide = 32;
using Dense = std::map<KeyTuple, float>;

MapNode NodeAt(int x, int y, int z, unsigned depth, float value) {
  return {MortonOf(Key({x, y, z})), value, static_cast<std::uint8_t>(depth)};
}

// A random grid over the cube: blocks of 1..8 voxels a side, disjoint, in Morton order.
RenderedGrid RandomGrid(std::mt19937& rng, double fill, const std::vector<float>& values) {
  RenderedGrid grid(0.05);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::uniform_int_distribution<std::size_t> pick(0, values.size() - 1);
  // Visit 8^k blocks top-down: keep a block whole, split it, or leave it out.
  std::function<void(int, int, int, unsigned)> visit = [&](int x, int y, int z, unsigned depth) {
    const int size = 1 << (kTreeDepth - depth);
    const double r = u(rng);
    if (depth < kTreeDepth && (size > 8 || r < 0.5)) {
      const int h = size / 2;
      for (int c = 0; c < 8; ++c) visit(x + (c & 1) * h, y + ((c >> 1) & 1) * h, z + (c >> 2) * h, depth + 1);
    } else if (u(rng) < fill) {
      grid.Append(NodeAt(x, y, z, depth, values[pick(rng)]));
    }
  };
  visit(kBase, kBase, kBase, kTreeDepth - 5);
  return grid;
}

void AddToDense(const RenderedGrid& grid, std::map<KeyTuple, std::vector<float>>* opinions) {
  for (const MapNode& n : grid.nodes()) {
    const octomap::OcTreeKey k = KeyOfMorton(n.code);
    const int s = 1 << (kTreeDepth - n.depth);
    for (int x = 0; x < s; ++x)
      for (int y = 0; y < s; ++y)
        for (int z = 0; z < s; ++z) (*opinions)[{k[0] + x, k[1] + y, k[2] + z}].push_back(n.log_odds);
  }
}

Dense DenseOf(const octomap::OcTree& tree) {
  Dense d;
  for (int x = kBase; x < kBase + kSide; ++x)
    for (int y = kBase; y < kBase + kSide; ++y)
      for (int z = kBase; z < kBase + kSide; ++z) {
        if (const auto* n = tree.search(Key({x, y, z}))) d[{x, y, z}] = n->getLogOdds();
      }
  return d;
}

// OctoMap's invariants: inner = max of the children, no collapsible node, no empty inner node.
void ExpectInvariants(const octomap::OcTree& tree, const octomap::OcTreeNode* node) {
  if (node == nullptr || !tree.nodeHasChildren(node)) return;
  float max_child = -1e30f;
  bool all_equal_leaves = true;
  const octomap::OcTreeNode* first = nullptr;
  for (unsigned i = 0; i < 8; ++i) {
    if (!tree.nodeChildExists(node, i)) {
      all_equal_leaves = false;
      continue;
    }
    const auto* c = tree.getNodeChild(node, i);
    max_child = std::max(max_child, c->getLogOdds());
    if (tree.nodeHasChildren(c)) all_equal_leaves = false;
    if (first == nullptr) first = c;
    if (c->getLogOdds() != first->getLogOdds()) all_equal_leaves = false;
    ExpectInvariants(tree, c);
  }
  ASSERT_NE(first, nullptr) << "inner node without children";
  EXPECT_FLOAT_EQ(node->getLogOdds(), max_child);
  EXPECT_FALSE(all_equal_leaves) << "collapsible node left";
}

TEST(FuseRegions, CoarseNodesReadAsTheirVoxels) {
  std::mt19937 rng(11);
  const RenderedGrid grid = RandomGrid(rng, 0.7, {-4.0f, -1.0f, 2.0f});
  ASSERT_TRUE(grid.IsValid());
  octomap::OcTree tree(0.05);
  std::vector<MapRegion> changed;
  FuseRegions(tree, FusionPolicy{}, {{nullptr, &grid}}, {&grid}, &changed);
  std::map<KeyTuple, std::vector<float>> opinions;
  AddToDense(grid, &opinions);
  const Dense got = DenseOf(tree);
  EXPECT_EQ(got.size(), opinions.size());
  for (const auto& [k, v] : opinions) {
    ASSERT_EQ(got.count(k), 1u);
    EXPECT_FLOAT_EQ(got.at(k), FusionPolicy{}.Fuse(v.data(), v.size()));
  }
  ExpectInvariants(tree, tree.getRoot());
  // Every node written is reported, in Morton order.
  EXPECT_EQ(changed.size(), grid.size());
  for (std::size_t i = 1; i < changed.size(); ++i) EXPECT_LT(changed[i - 1].code, changed[i].code);
  // Coarse leaves stay coarse: fewer leaves than voxels.
  EXPECT_LT(tree.getNumLeafNodes(), got.size() / 2);
}

// A render decides a mixed block's voxels one by one; where they come out with one value (or
// nodes of one value fill a block), the block is written whole: one changed region, not a leaf
// per node that the tree then prunes. Over a history that differs inside the block, every voxel
// still gets its own fused value.
TEST(FuseRegions, NodesOfOneValueFillingABlockAreWrittenAsTheBlock) {
  std::vector<MapNode> nodes;
  const auto voxels = [&nodes](int x, int y, int z, int side, const std::vector<float>& values) {
    for (int i = 0; i < side * side * side; ++i) {
      const float v = values[static_cast<std::size_t>(i) % values.size()];
      nodes.push_back(NodeAt(x + i % side, y + (i / side) % side, z + i / (side * side), 16, v));
    }
  };
  voxels(kBase, kBase, kBase, 4, {-2.0f});  // 64 voxels of one value: their depth-14 block
  for (int c = 0; c < 8; ++c) {             // 8 depth-15 nodes of one value: the same
    nodes.push_back(NodeAt(kBase + 4 + (c & 1) * 2, kBase + ((c >> 1) & 1) * 2,
                           kBase + (c >> 2) * 2, 15, -2.0f));
  }
  voxels(kBase + 8, kBase, kBase, 2, {-1.0f});  // one depth-15 block of 8 equal voxels ...
  for (int c = 1; c < 8; ++c) {                 // ... beside 7 depth-15 nodes of two values
    nodes.push_back(NodeAt(kBase + 8 + (c & 1) * 2, kBase + ((c >> 1) & 1) * 2,
                           kBase + (c >> 2) * 2, 15, c % 2 == 0 ? 1.5f : 2.5f));
  }
  voxels(kBase + 12, kBase, kBase, 2, {-1.0f, -1.0f, 0.5f});  // 8 voxels, not of one value
  std::sort(nodes.begin(), nodes.end(),
            [](const MapNode& a, const MapNode& b) { return a.code < b.code; });
  RenderedGrid grid(0.05);
  for (const MapNode& n : nodes) grid.Append(n);
  ASSERT_TRUE(grid.IsValid());

  octomap::OcTree tree(0.05);
  std::vector<MapRegion> changed;
  FuseRegions(tree, FusionPolicy{}, {{nullptr, &grid}}, {&grid}, &changed);
  std::vector<MapRegion> expected{{MortonOf(Key({kBase, kBase, kBase})), 14},
                                  {MortonOf(Key({kBase + 4, kBase, kBase})), 14}};
  for (int c = 0; c < 8; ++c) {
    expected.push_back(
        {MortonOf(Key({kBase + 8 + (c & 1) * 2, kBase + ((c >> 1) & 1) * 2, kBase + (c >> 2) * 2})),
         15});
  }
  for (const MapNode& n : nodes) {
    if (KeyOfMorton(n.code)[0] >= kBase + 12) expected.push_back({n.code, 16});
  }
  EXPECT_EQ(changed, expected);
  std::map<KeyTuple, std::vector<float>> opinions;
  AddToDense(grid, &opinions);
  Dense want;
  for (const auto& [k, v] : opinions) want[k] = v.front();
  EXPECT_EQ(DenseOf(tree), want);
  ExpectInvariants(tree, tree.getRoot());

  // Over a history of random voxels: each voxel fused on its own.
  std::mt19937 rng(41);
  const RenderedGrid h = RandomGrid(rng, 0.9, {-3.0f, -1.0f, 1.5f});
  octomap::OcTree history(0.05);
  FuseRegions(history, FusionPolicy{}, {{nullptr, &h}}, {&h});
  const FusionPolicy policy = FusionPolicy::Make(FusionRule::kIndependentOpinionPool, 0.01, 0.99);
  octomap::OcTree fused(history);
  FuseRegions(fused, policy, {{&history, nullptr}, {nullptr, &grid}}, {&grid});
  std::map<KeyTuple, std::vector<float>> all;
  AddToDense(h, &all);
  AddToDense(grid, &all);
  const Dense got = DenseOf(fused);
  for (const auto& [k, v] : opinions) {
    ASSERT_EQ(got.count(k), 1u);
    EXPECT_FLOAT_EQ(got.at(k), policy.Fuse(all.at(k).data(), all.at(k).size()));
  }
  ExpectInvariants(fused, fused.getRoot());
}

TEST(FuseRegions, HistoryAndGridsFuseOnlyWhereTheDriverSays) {
  std::mt19937 rng(12);
  const FusionPolicy policy = FusionPolicy::Make(FusionRule::kIndependentOpinionPool, 0.01, 0.99);
  const RenderedGrid history_grid = RandomGrid(rng, 0.8, {-3.0f, 1.5f});
  octomap::OcTree history(0.05);
  FuseRegions(history, FusionPolicy{}, {{nullptr, &history_grid}}, {&history_grid});
  const RenderedGrid a = RandomGrid(rng, 0.6, {-2.0f, 0.5f, 3.0f});
  const RenderedGrid b = RandomGrid(rng, 0.6, {-1.0f, 2.5f});
  // The fused map starts as the history, then the two grids arrive; b drives the second step.
  octomap::OcTree fused(history);
  FuseRegions(fused, policy, {{&history, nullptr}, {nullptr, &a}}, {&a});
  std::vector<MapRegion> changed;
  FuseRegions(fused, policy, {{&history, nullptr}, {nullptr, &a}, {nullptr, &b}}, {&b}, &changed);
  std::map<KeyTuple, std::vector<float>> with_a, all;
  AddToDense(history_grid, &with_a);
  AddToDense(a, &with_a);
  all = with_a;
  AddToDense(b, &all);
  std::map<KeyTuple, std::vector<float>> in_b;
  AddToDense(b, &in_b);
  const Dense got = DenseOf(fused);
  const Dense before = [&] {
    octomap::OcTree t(history);
    FuseRegions(t, policy, {{&history, nullptr}, {nullptr, &a}}, {&a});
    return DenseOf(t);
  }();
  for (int x = kBase; x < kBase + kSide; ++x)
    for (int y = kBase; y < kBase + kSide; ++y)
      for (int z = kBase; z < kBase + kSide; ++z) {
        const KeyTuple k{x, y, z};
        if (in_b.count(k) != 0) {
          const auto& v = all.at(k);
          ASSERT_EQ(got.count(k), 1u);
          EXPECT_FLOAT_EQ(got.at(k), policy.Fuse(v.data(), v.size()));
        } else {
          // Outside b's nodes: what the map held (history fused with a where a said something).
          ASSERT_EQ(got.count(k), before.count(k));
          if (got.count(k) != 0) EXPECT_FLOAT_EQ(got.at(k), before.at(k));
        }
      }
  ExpectInvariants(fused, fused.getRoot());
  // The changed regions cover exactly the voxels whose value changed.
  std::map<KeyTuple, bool> reported;
  for (const MapRegion& r : changed) {
    const octomap::OcTreeKey k = KeyOfMorton(r.code);
    const int s = 1 << (kTreeDepth - r.depth);
    for (int x = 0; x < s; ++x)
      for (int y = 0; y < s; ++y)
        for (int z = 0; z < s; ++z) reported[{k[0] + x, k[1] + y, k[2] + z}] = true;
  }
  for (int x = kBase; x < kBase + kSide; ++x)
    for (int y = kBase; y < kBase + kSide; ++y)
      for (int z = kBase; z < kBase + kSide; ++z) {
        const KeyTuple k{x, y, z};
        const bool differs = got.count(k) != before.count(k) ||
                             (got.count(k) != 0 && got.at(k) != before.at(k));
        if (differs) EXPECT_TRUE(reported.count(k) != 0);
        if (reported.count(k) != 0) EXPECT_TRUE(in_b.count(k) != 0);
      }
}

TEST(CopyRegions, BringsAnOlderCopyUpToDate) {
  std::mt19937 rng(13);
  const FusionPolicy policy;
  const RenderedGrid first = RandomGrid(rng, 0.7, {-2.0f, 1.0f});
  octomap::OcTree source(0.05);
  FuseRegions(source, policy, {{nullptr, &first}}, {&first});
  octomap::OcTree copy(source);
  // Three more changes to the source, one of them removing what a grid covers.
  std::vector<MapRegion> changed;
  for (int step = 0; step < 3; ++step) {
    const RenderedGrid g = RandomGrid(rng, 0.5, {-3.0f, 0.5f, 2.0f});
    if (step == 1) {
      FuseRegions(source, policy, {}, {&g}, &changed);
    } else {
      FuseRegions(source, policy, {{&source, nullptr}, {nullptr, &g}}, {&g}, &changed);
    }
  }
  NormaliseRegions(&changed);
  CopyRegions(copy, source, changed);
  EXPECT_EQ(DenseOf(copy), DenseOf(source));
  EXPECT_EQ(copy.size(), source.size());
  ExpectInvariants(copy, copy.getRoot());
}

// Catching up inside the fuse's walk gives what fusing into a copy of the tree caught up with
// gives: the same tree, node for node, and the same changed regions, over random histories,
// lags and drivers (with none: CopyRegions).
TEST(FuseRegions, CatchingUpInTheSameWalkIsCopyingFirst) {
  std::mt19937 rng(21);
  const FusionPolicy policy = FusionPolicy::Make(FusionRule::kIndependentOpinionPool, 0.01, 0.99);
  for (int trial = 0; trial < 12; ++trial) {
    const RenderedGrid h = RandomGrid(rng, 0.8, {-3.0f, -1.0f, 1.5f});
    octomap::OcTree history(0.05);
    FuseRegions(history, FusionPolicy{}, {{nullptr, &h}}, {&h});
    // The published tree and a spare one version behind it.
    const RenderedGrid first = RandomGrid(rng, 0.6, {-2.0f, 0.5f});
    octomap::OcTree published(history);
    FuseRegions(published, policy, {{&history, nullptr}, {nullptr, &first}}, {&first});
    const octomap::OcTree spare_before(published);
    const RenderedGrid second = RandomGrid(rng, 0.5, {-2.0f, 0.5f, 2.5f});
    std::vector<MapRegion> lag;
    if (trial % 3 == 1) {
      FuseRegions(published, policy, {}, {&second}, &lag);  // the version removed a grid's cover
    } else {
      FuseRegions(published, policy, {{&history, nullptr}, {nullptr, &second}}, {&second}, &lag);
    }
    NormaliseRegions(&lag);
    // The next write: a live grid fused over the history where it leads (and, in some trials,
    // where `second` does: then every lagging region is fused, none copied).
    const RenderedGrid live = RandomGrid(rng, trial % 4 == 0 ? 0.0 : 0.6, {-4.0f, 1.0f, 3.0f});
    const std::vector<MergeSource> sources{{&history, nullptr}, {nullptr, &live}};
    std::vector<const RenderedGrid*> drivers{&live};
    if (trial % 3 == 2) drivers.push_back(&second);
    octomap::OcTree expected(published);  // the spare caught up: a deep copy, no merge
    std::vector<MapRegion> expected_changed;
    FuseRegions(expected, policy, sources, drivers, &expected_changed);
    octomap::OcTree got(spare_before);
    std::vector<MapRegion> got_changed;
    RenderedGrid buffer(0.05);
    const CatchUp catch_up{&published, &lag, &buffer};
    FuseRegions(got, policy, sources, drivers, &got_changed, &catch_up);
    EXPECT_EQ(DenseOf(got), DenseOf(expected)) << "trial " << trial;
    EXPECT_EQ(got.size(), expected.size()) << "trial " << trial;
    EXPECT_EQ(got.getNumLeafNodes(), expected.getNumLeafNodes()) << "trial " << trial;
    ExpectInvariants(got, got.getRoot());
    EXPECT_EQ(got_changed, expected_changed) << "trial " << trial;
    if (!lag.empty()) EXPECT_NE(DenseOf(spare_before), DenseOf(published)) << "trial " << trial;
  }
}

// Every merge reports how the target's leaf count changed, exactly as OctoMap counts the
// leaves afterwards: over fusing, removing (no sources), pruning (few values: blocks collapse),
// splitting coarse leaves, catching up in the walk, copying, and emptying the tree.
TEST(FuseRegions, ReportsHowTheLeafCountChanged) {
  std::mt19937 rng(31);
  const FusionPolicy policy = FusionPolicy::Make(FusionRule::kIndependentOpinionPool, 0.01, 0.99);
  octomap::OcTree tree(0.05), lagging(0.05);
  std::size_t leaves = 0, lagging_leaves = 0;
  const auto add = [](std::size_t* count, std::int64_t delta) {
    *count = static_cast<std::size_t>(static_cast<std::int64_t>(*count) + delta);
  };
  for (int step = 0; step < 40; ++step) {
    const bool few = step % 2 == 0;
    const RenderedGrid g = RandomGrid(rng, 0.3 + 0.1 * (step % 6),
                                      few ? std::vector<float>{-2.0f} : std::vector<float>{-2.0f, 1.0f, 3.0f});
    std::vector<MapRegion> changed;
    std::int64_t added = 0;
    if (step % 5 == 3) {
      FuseRegions(tree, policy, {}, {&g}, &changed, nullptr, &added);  // removes g's cover
    } else if (step % 7 == 6) {
      FuseRegions(tree, policy, {{nullptr, &g}}, {&g}, &changed, nullptr, &added);  // overwrites
    } else {
      FuseRegions(tree, policy, {{&tree, nullptr}, {nullptr, &g}}, {&g}, &changed, nullptr,
                  &added);
    }
    add(&leaves, added);
    ASSERT_EQ(leaves, tree.getNumLeafNodes()) << "step " << step;
    // The lagging copy catches up every other step, alternately in a merge's walk and by a copy.
    NormaliseRegions(&changed);
    std::int64_t caught = 0;
    if (step % 4 == 1) {
      const RenderedGrid h = RandomGrid(rng, 0.5, {-1.0f, 2.0f});
      const CatchUp catch_up{&tree, &changed, nullptr};
      FuseRegions(lagging, policy, {{nullptr, &h}}, {&h}, nullptr, &catch_up, &caught);
    } else {
      CopyRegions(lagging, tree, changed, nullptr, &caught);
    }
    add(&lagging_leaves, caught);
    ASSERT_EQ(lagging_leaves, lagging.getNumLeafNodes()) << "step " << step;
    if (step % 4 == 1) {  // h's regions differ: the whole tree copied back
      std::int64_t copied = 0;
      CopyRegions(lagging, tree, {{0, 0}}, nullptr, &copied);
      add(&lagging_leaves, copied);
      ASSERT_EQ(lagging_leaves, lagging.getNumLeafNodes()) << "step " << step;
    }
    ASSERT_EQ(DenseOf(lagging), DenseOf(tree)) << "step " << step;
  }
  // Everything removed: the tree is empty and the count 0.
  RenderedGrid all(0.05);
  all.Append({0, 0.0f, 0});
  std::int64_t added = 0;
  FuseRegions(tree, policy, {}, {&all}, nullptr, nullptr, &added);
  add(&leaves, added);
  EXPECT_EQ(tree.getRoot(), nullptr);
  EXPECT_EQ(leaves, 0u);
}

// The cover of a box, checked voxel by voxel with OctoMap's own key-to-centre conversion, and
// clearing it (CopyRegions from an empty tree) leaves every other voxel as it was.
TEST(RegionsInBox, TileExactlyTheVoxelsWhoseCentresLieInTheBox) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int trial = 0; trial < 12; ++trial) {
    const RenderedGrid grid = RandomGrid(rng, 0.8, {-3.0f, 1.5f});
    octomap::OcTree tree(0.05);
    FuseRegions(tree, FusionPolicy{}, {{nullptr, &grid}}, {&grid});
    // Boxes around the cube's middle (the cube spans [-0.8, 0.8] m), faces off the voxel grid.
    Eigen::Vector3d a(u(rng), u(rng), u(rng)), b(u(rng), u(rng), u(rng));
    const Eigen::AlignedBox3d box(a.cwiseMin(b) * 0.8, a.cwiseMax(b) * 0.8);
    const auto in_box = [&](const KeyTuple& k) {
      const octomap::point3d c = tree.keyToCoord(Key(k));
      return box.contains(Eigen::Vector3d(c.x(), c.y(), c.z()));
    };
    const std::vector<MapRegion> regions = RegionsInBox(tree, box);
    std::map<KeyTuple, int> covered;
    for (std::size_t r = 0; r < regions.size(); ++r) {
      if (r > 0) {
        ASSERT_GE(regions[r].code, regions[r - 1].code + MortonSpan(regions[r - 1].depth));
      }
      const octomap::OcTreeKey k = KeyOfMorton(regions[r].code);
      const int size = 1 << (kTreeDepth - regions[r].depth);
      EXPECT_TRUE(in_box({k[0], k[1], k[2]}) &&
                  in_box({k[0] + size - 1, k[1] + size - 1, k[2] + size - 1}))
          << "region " << r << " reaches outside the box";
      for (int x = 0; x < size; ++x)
        for (int y = 0; y < size; ++y)
          for (int z = 0; z < size; ++z) ++covered[{k[0] + x, k[1] + y, k[2] + z}];
    }
    const Dense before = DenseOf(tree);
    Dense expected;
    for (const auto& [k, v] : before) {
      if (in_box(k)) {
        EXPECT_EQ(covered.count(k), 1u) << "a voxel in the box is not covered";
      } else {
        expected[k] = v;
      }
    }
    CopyRegions(tree, octomap::OcTree(0.05), regions);
    EXPECT_EQ(DenseOf(tree), expected) << "trial " << trial;
    ExpectInvariants(tree, tree.getRoot());
  }
  EXPECT_TRUE(RegionsInBox(octomap::OcTree(0.05), Eigen::AlignedBox3d(Eigen::Vector3d::Zero(),
                                                                       Eigen::Vector3d::Ones()))
                  .empty());
}

TEST(NormaliseRegions, DropsNestedRegions) {
  std::vector<MapRegion> r = {{MortonOf(Key({8, 8, 8})), 16},
                              {MortonOf(Key({8, 8, 8})), 14},
                              {MortonOf(Key({0, 0, 0})), 16},
                              {MortonOf(Key({9, 9, 9})), 16}};
  NormaliseRegions(&r);
  ASSERT_EQ(r.size(), 2u);
  EXPECT_EQ(r[0].code, MortonOf(Key({0, 0, 0})));
  EXPECT_EQ(r[1].depth, 14);
}

TEST(Morton, RoundTripsAndOrdersLikeOctoMap) {
  std::mt19937 rng(3);
  std::uniform_int_distribution<int> k(0, 65535);
  for (int i = 0; i < 10000; ++i) {
    const octomap::OcTreeKey key(k(rng), k(rng), k(rng));
    EXPECT_EQ(KeyOfMorton(MortonOf(key)), key);
    // The three bits of each level are OctoMap's child index there.
    const std::uint64_t code = MortonOf(key);
    for (int level = 0; level < 16; ++level) {
      EXPECT_EQ((code >> (3 * level)) & 7u, octomap::computeChildIdx(key, level));
    }
  }
  // NodeKey is the key OctoMap's iterators report for a pruned node.
  octomap::OcTree tree(0.05);
  for (int x = 0; x < 4; ++x)
    for (int y = 0; y < 4; ++y)
      for (int z = 0; z < 4; ++z) tree.setNodeValue(octomap::OcTreeKey(64 + x, 128 + y, 256 + z), 1.0f);
  tree.prune();
  auto it = tree.begin_leafs();
  ASSERT_EQ(it.getDepth(), 14u);
  EXPECT_EQ(it.getKey(), NodeKey(MortonOf(octomap::OcTreeKey(64, 128, 256)), 14));
}

}  // namespace
}  // namespace fusion
