#include "fusion/core/octree_edit.h"

namespace fusion {

bool DeleteVoxel(octomap::OcTree& tree, const octomap::OcTreeKey& key) {
  constexpr unsigned kMaxDepth = 16;
  const unsigned depth = tree.getTreeDepth();
  octomap::OcTreeNode* node = tree.getRoot();
  if (node == nullptr || depth > kMaxDepth) return false;
  // First pass: is the key held at all (leaf or pruned node)? Nothing changes if not.
  for (unsigned d = 0; d < depth; ++d) {
    const unsigned child = octomap::computeChildIdx(key, static_cast<int>(depth - 1 - d));
    if (!tree.nodeChildExists(node, child)) {
      if (tree.nodeHasChildren(node)) return false;  // no branch towards the key
      break;                                         // a pruned node holds it
    }
    node = tree.getNodeChild(node, child);
  }
  // Second pass: the path to the leaf, splitting pruned nodes on the way.
  octomap::OcTreeNode* path[kMaxDepth + 1];
  unsigned index[kMaxDepth + 1];
  path[0] = node = tree.getRoot();
  for (unsigned d = 0; d < depth; ++d) {
    const unsigned child = octomap::computeChildIdx(key, static_cast<int>(depth - 1 - d));
    if (!tree.nodeChildExists(node, child)) tree.expandNode(node);
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
