#include "fusion/core/octree_edit.h"

#include <gtest/gtest.h>

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
