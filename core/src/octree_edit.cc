#include "fusion/core/octree_edit.h"

namespace fusion {

bool DeleteVoxel(octomap::OcTree& tree, const octomap::OcTreeKey& key) {
  constexpr unsigned kMaxDepth = 16;
  const unsigned depth = tree.getTreeDepth();
  octomap::OcTreeNode* node = tree.getRoot();
  if (node == nullptr || depth > kMaxDepth) return false;
  // The path to the leaf. Where the key's branch ends, a node without children is a pruned
  // block holding the key: split it (its children are leaves again, so the descent goes on
  // down to the key). A node with other children but none towards the key does not hold it;
  // that can only happen before the first split, so nothing has changed then.
  octomap::OcTreeNode* path[kMaxDepth + 1];
  unsigned index[kMaxDepth + 1];
  path[0] = node;
  for (unsigned d = 0; d < depth; ++d) {
    const unsigned child = octomap::computeChildIdx(key, static_cast<int>(depth - 1 - d));
    if (!tree.nodeChildExists(node, child)) {
      if (tree.nodeHasChildren(node)) return false;
      tree.expandNode(node);
    }
    index[d + 1] = child;
    node = tree.getNodeChild(node, child);
    path[d + 1] = node;
  }
  // Delete the leaf, then every ancestor it leaves empty. An emptied node still owns its child
  // array: expanding and pruning it again is the public way to release that.
  unsigned d = depth;
  for (; d > 0; --d) {
    octomap::OcTreeNode* parent = path[d - 1];
    tree.deleteNodeChild(parent, index[d]);
    if (tree.nodeHasChildren(parent)) break;
    tree.expandNode(parent);
    tree.pruneNode(parent);
  }
  if (d == 0) {  // the root lost its last child: the tree is empty
    tree.clear();
    return true;
  }
  for (unsigned k = d; k-- > 0;) path[k]->updateOccupancyChildren();
  return true;
}

}  // namespace fusion
