// Edits of an OctoMap tree that OctoMap 1.9 does not do safely.
#pragma once

#include <octomap/OcTree.h>

namespace fusion {

// Removes the full-depth voxel `key` from `tree`: splits a pruned node that holds it, deletes
// its leaf and every inner node left without children, and refreshes the inner values (max of
// the children, as OctoMap keeps them) above. Afterwards search(key) finds nothing and every
// other voxel keeps its value. Returns false (tree unchanged) if no node holds the key.
//
// OctoMap 1.9's deleteNode leaves an emptied inner node with its child array allocated and
// then deletes the node (an assertion in debug builds, a leak otherwise); this releases the
// array first.
bool DeleteVoxel(octomap::OcTree& tree, const octomap::OcTreeKey& key);

}  // namespace fusion
