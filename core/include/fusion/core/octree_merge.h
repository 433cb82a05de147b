// Writing multi-resolution contributions into an OctoMap tree, region by region: the one way the
// fused map, the committed history and the published copies of the map are changed.
//
// A region is an octree node (Morton code of its first voxel and depth, 16 = one voxel). The tree
// keeps OctoMap's own invariants after every merge: an inner node holds the maximum of its
// children (as OcTree::updateInnerOccupancy), a node whose eight children are leaves of one
// value is pruned into a leaf of that value (as OcTree::prune), and no inner node is left
// without children. So a uniform block, such as free space decided whole by the projective
// render, is one coarse leaf, exactly as OctoMap's pruning represents it, and every OcTree
// reader (search, iterators, castRay, .ot / .bt writers) reads it correctly.
#pragma once

#include <octomap/OcTree.h>

#include <Eigen/Geometry>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <vector>

#include "fusion/core/fusion_rules.h"
#include "fusion/core/rendered_grid.h"

namespace fusion {

struct MapRegion {
  std::uint64_t code = 0;
  std::uint8_t depth = kTreeDepth;
  friend bool operator==(const MapRegion& a, const MapRegion& b) {
    return a.code == b.code && a.depth == b.depth;
  }
};

// An opinion about the map: a tree (log-odds per leaf) or a rendered grid; where it has no node
// it has no opinion.
struct MergeSource {
  const octomap::OcTree* tree = nullptr;
  const RenderedGrid* grid = nullptr;
};

// A tree the target lags behind in some regions (ascending codes, disjoint): FuseRegions brings
// it up to date there in the same walk (see below). buffer (may be null): kept between calls.
struct CatchUp {
  const octomap::OcTree* reference = nullptr;
  const std::vector<MapRegion>* regions = nullptr;
  RenderedGrid* buffer = nullptr;
};

// target := policy.Fuse(opinions of the sources) in every region where some driver has a node
// (sources without an opinion left out; none at all: the region is removed). Regions no driver
// touches keep what they hold. Sources and target must share the resolution; the target may
// be one of the sources. Appends the regions whose value changed (removed included) in Morton
// order to *changed, if not null. A grid's few nodes of one value that fill a region (a
// render's voxels decided one by one) count as one node of the region: it is written whole,
// and reported as one region.
// With a catch-up, the target first becomes the reference in its regions (as CopyRegions),
// except where a driver leads, whose fused value is written directly; a region counts as
// changed there when its value differs from the reference's. One walk instead of a copy and a
// fuse over the same regions. The target must not be one of the sources then.
// Adds how the target's leaf count (OcTree::getNumLeafNodes) changed to *leaves_added, if not
// null: a caller that keeps the count has it without walking the tree.
void FuseRegions(octomap::OcTree& target, const FusionPolicy& policy,
                 const std::vector<MergeSource>& sources,
                 const std::vector<const RenderedGrid*>& drivers,
                 std::vector<MapRegion>* changed = nullptr, const CatchUp* catch_up = nullptr,
                 std::int64_t* leaves_added = nullptr);

// target := source in the given regions (ascending codes, disjoint): what source holds there,
// nothing where it holds nothing. `scratch` (may be null): a buffer kept between calls.
// leaves_added: as FuseRegions'.
void CopyRegions(octomap::OcTree& target, const octomap::OcTree& source,
                 const std::vector<MapRegion>& regions, RenderedGrid* scratch = nullptr,
                 std::int64_t* leaves_added = nullptr);

// OcTree::memoryUsage()'s figure for a tree with `leaves` leaves, without the walk that
// memoryUsage makes to count them (the node count, OcTree::size, is kept by OctoMap).
[[nodiscard]] std::size_t TreeMemoryBytes(const octomap::OcTree& tree, std::size_t leaves);

// Removes the full-depth voxel `key` from `tree` (splits a pruned node holding it); false if no
// node holds it. Every other voxel keeps its value.
bool DeleteVoxel(octomap::OcTree& tree, const octomap::OcTreeKey& key);

// What `tree` holds in `region`, piece by piece, depth first: f(key, depth, node) for every leaf
// inside the region; the region itself with the leaf that holds it if that leaf is coarser; the
// region with a null node if the tree holds nothing there. Keys are OctoMap's (node centre).
void ForEachInRegion(
    const octomap::OcTree& tree, const MapRegion& region,
    const std::function<void(const octomap::OcTreeKey&, unsigned, const octomap::OcTreeNode*)>& f);

// The regions that tile the voxels whose centres lie in `box_world` (closed; world frame) where
// `tree` has nodes: nodes wholly inside whole, coarse leaves across the box's faces split down
// to the voxels along them. Ascending codes, disjoint; empty where the tree holds nothing.
[[nodiscard]] std::vector<MapRegion> RegionsInBox(const octomap::OcTree& tree,
                                                  const Eigen::AlignedBox3d& box_world);

// Regions sorted by code, with every region that lies inside an earlier one dropped.
void NormaliseRegions(std::vector<MapRegion>* regions);

}  // namespace fusion
