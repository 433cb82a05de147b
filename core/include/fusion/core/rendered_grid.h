// A rendered contribution at several resolutions: disjoint octree nodes of the world map, each a
// voxel (depth 16) or a block of 8^(16 - depth) voxels with one value, in Morton (depth-first,
// OctoMap child) order, so that a subtree of the map is a contiguous run of nodes.
#pragma once

#include <octomap/OcTree.h>

#include <cstddef>
#include <cstdint>
#include <optional>
#include <vector>

namespace fusion {

class LocalGrid;

inline constexpr unsigned kTreeDepth = 16;  // OctoMap's depth: keys of 16 bits per axis

// Morton code of a full-depth key: bit 3i + a is bit i of key.k[a], so that the three bits at
// level i are OctoMap's child index (octomap::computeChildIdx) and sorting by code is a
// depth-first walk of the tree.
[[nodiscard]] std::uint64_t MortonOf(const octomap::OcTreeKey& key);
[[nodiscard]] octomap::OcTreeKey KeyOfMorton(std::uint64_t code);
// Codes a node at `depth` covers: [code, code + MortonSpan(depth)).
[[nodiscard]] inline std::uint64_t MortonSpan(unsigned depth) {
  return std::uint64_t{1} << (3 * (kTreeDepth - depth));
}
// The code of the node at `depth` holding `code` (its first voxel).
[[nodiscard]] inline std::uint64_t MortonAtDepth(std::uint64_t code, unsigned depth) {
  return code & ~(MortonSpan(depth) - 1);
}
// OctoMap's key of a node (its centre key, as its iterators report it).
[[nodiscard]] octomap::OcTreeKey NodeKey(std::uint64_t code, unsigned depth);

struct MapNode {
  std::uint64_t code = 0;  // Morton code of the node's first voxel
  float log_odds = 0.0f;
  std::uint8_t depth = kTreeDepth;
};

class RenderedGrid {
 public:
  explicit RenderedGrid(double resolution_m = 0.02) : resolution_m_(resolution_m) {}
  // Empty, appending into `storage`'s memory (a spent grid's: see TakeStorage).
  RenderedGrid(double resolution_m, std::vector<MapNode> storage)
      : resolution_m_(resolution_m), nodes_(std::move(storage)) {
    nodes_.clear();
  }
  // Every voxel of a local grid that holds evidence (sorted into Morton order); one at
  // log-odds 0 says nothing and is left out, as the map holds no node at 0.
  [[nodiscard]] static RenderedGrid FromLocalGrid(const LocalGrid& local);

  [[nodiscard]] double resolution_m() const { return resolution_m_; }
  [[nodiscard]] const std::vector<MapNode>& nodes() const { return nodes_; }
  [[nodiscard]] bool empty() const { return nodes_.empty(); }
  [[nodiscard]] std::size_t size() const { return nodes_.size(); }
  // Voxels covered (a node at depth d covers 8^(16 - d)).
  [[nodiscard]] std::uint64_t VoxelCount() const;
  // Value of the node holding a full-depth key; std::nullopt where the grid has none.
  [[nodiscard]] std::optional<float> LogOddsAt(const octomap::OcTreeKey& key) const;
  // Appends a node after every node so far (codes ascending, disjoint: not checked here; see
  // IsValid).
  void Append(const MapNode& node) { nodes_.push_back(node); }
  void Clear() { nodes_.clear(); }
  // The nodes' memory, for a grid made later; this grid is left empty.
  [[nodiscard]] std::vector<MapNode> TakeStorage() {
    std::vector<MapNode> storage = std::move(nodes_);
    nodes_ = {};
    return storage;
  }
  // Sorted, disjoint, depths in [0, 16], codes aligned to their depth.
  [[nodiscard]] bool IsValid() const;
  [[nodiscard]] std::size_t MemoryBytes() const { return nodes_.capacity() * sizeof(MapNode); }

 private:
  double resolution_m_;
  std::vector<MapNode> nodes_;
};

}  // namespace fusion
