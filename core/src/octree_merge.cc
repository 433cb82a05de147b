#include "fusion/core/octree_merge.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <optional>
#include <stdexcept>

namespace fusion::detail {
struct ChildArrayAccess {};
}  // namespace fusion::detail

// OctoMap keeps a node's child array private to its tree classes (every OcTreeBaseImpl is a
// friend of OcTreeDataNode). Its public API cannot release the array of a node whose children
// were all deleted (deleteNodeChild deletes one child and leaves the array), which a merge that
// removes or collapses subtrees must do. This specialisation, for a tag type of ours that OctoMap
// never instantiates, is that friend for exactly one thing.
namespace octomap {
template <>
class OcTreeBaseImpl<fusion::detail::ChildArrayAccess, fusion::detail::ChildArrayAccess> {
 public:
  static void ReleaseEmptyChildArray(OcTreeNode* node) {
    OcTreeDataNode<float>* data = node;
    delete[] data->children;
    data->children = nullptr;
  }
  static bool HasChildArray(const OcTreeNode* node) {
    const OcTreeDataNode<float>* data = node;
    return data->children != nullptr;
  }
};
}  // namespace octomap

namespace fusion {
namespace {

using Access = octomap::OcTreeBaseImpl<detail::ChildArrayAccess, detail::ChildArrayAccess>;
using Node = octomap::OcTreeNode;

// Deletes child `i` of `parent` with its whole subtree.
void DeleteSubtree(octomap::OcTree& tree, Node* parent, unsigned i) {
  Node* node = tree.getNodeChild(parent, i);
  if (Access::HasChildArray(node)) {
    for (unsigned j = 0; j < 8; ++j) {
      if (tree.nodeChildExists(node, j)) DeleteSubtree(tree, node, j);
    }
    Access::ReleaseEmptyChildArray(node);
  }
  tree.deleteNodeChild(parent, i);
}

// Deletes every child of `node`, which becomes a leaf.
void MakeLeaf(octomap::OcTree& tree, Node* node) {
  if (!Access::HasChildArray(node)) return;
  for (unsigned j = 0; j < 8; ++j) {
    if (tree.nodeChildExists(node, j)) DeleteSubtree(tree, node, j);
  }
  Access::ReleaseEmptyChildArray(node);
}

// The root of a tree, created (a leaf, value 0) if the tree is empty. OcTree creates its root
// only on the way to a voxel: create that path, then cut it off below the root.
Node* EnsureRoot(octomap::OcTree& tree) {
  if (tree.getRoot() == nullptr) {
    tree.setNodeValue(octomap::OcTreeKey(0, 0, 0), 0.0f, /*lazy_eval=*/true);
    MakeLeaf(tree, tree.getRoot());
  }
  return tree.getRoot();
}

// What one opinion (a source) or one driver holds inside a region.
struct Cursor {
  enum Kind : std::uint8_t { kNone, kUniform, kTree, kGrid };
  Kind kind = kNone;
  float value = 0.0f;                // kUniform
  const Node* node = nullptr;        // kTree: a node with children
  const MapNode* lo = nullptr;       // kGrid: the nodes inside the region, all deeper than it
  const MapNode* hi = nullptr;
};

Cursor TreeCursor(const octomap::OcTree& tree, const Node* node) {
  Cursor c;
  if (node == nullptr) return c;
  if (!tree.nodeHasChildren(node)) {
    c.kind = Cursor::kUniform;
    c.value = node->getLogOdds();
  } else {
    c.kind = Cursor::kTree;
    c.node = node;
  }
  return c;
}

Cursor GridCursor(const MapNode* lo, const MapNode* hi, unsigned depth) {
  Cursor c;
  if (lo == hi) return c;
  if (lo->depth <= depth) {  // a node covering the whole region (the only one in it)
    c.kind = Cursor::kUniform;
    c.value = lo->log_odds;
  } else {
    c.kind = Cursor::kGrid;
    c.lo = lo;
    c.hi = hi;
  }
  return c;
}

// End of the nodes of [lo, hi) (ascending codes) that start before `code`: none when the first
// does not, a short scan for the few nodes a fine region holds, a binary search for many.
const MapNode* Before(const MapNode* lo, const MapNode* hi, std::uint64_t code) {
  if (lo == hi || lo->code >= code) return lo;
  if (hi - lo <= 16) {
    while (lo != hi && lo->code < code) ++lo;
    return lo;
  }
  return std::lower_bound(lo, hi, code,
                          [](const MapNode& n, std::uint64_t c) { return n.code < c; });
}

// *out := the cursor of child `child` of a region at `depth` starting at `code`. For a grid,
// `*next` is where the nodes not yet handed to a child begin; children may be skipped, and the
// cursor starts at the child's own first node. `*next` is moved past the child's nodes.
void ChildCursor(const Cursor& parent, const octomap::OcTree* tree, unsigned depth,
                 std::uint64_t code, unsigned child, const MapNode** next, Cursor* out) {
  switch (parent.kind) {
    case Cursor::kNone:
    case Cursor::kUniform:
      *out = parent;
      return;
    case Cursor::kTree:
      *out = TreeCursor(*tree, tree->nodeChildExists(parent.node, child)
                                   ? tree->getNodeChild(parent.node, child)
                                   : nullptr);
      return;
    case Cursor::kGrid: {
      const std::uint64_t span = MortonSpan(depth + 1);
      const std::uint64_t begin = code + child * span;
      const MapNode* lo = Before(*next, parent.hi, begin);
      const MapNode* hi = Before(lo, parent.hi, begin + span);
      *next = hi;
      *out = GridCursor(lo, hi, depth + 1);
      return;
    }
  }
  *out = Cursor{};
}

// One merge: the target, the sources and drivers, and how opinions become a value.
class Merge {
 public:
  enum class Mode { kFuse, kCopy };
  static constexpr std::size_t kMaxInputs = 16;

  Merge(octomap::OcTree& target, Mode mode, const FusionPolicy& policy,
        std::vector<const octomap::OcTree*> source_trees, std::vector<MapRegion>* changed)
      : target_(target),
        mode_(mode),
        policy_(policy),
        source_trees_(std::move(source_trees)),
        changed_(changed) {}

  void Run(const std::vector<Cursor>& sources, const std::vector<Cursor>& drivers) {
    if (sources.size() > kMaxInputs || drivers.size() > kMaxInputs) {
      throw std::invalid_argument("FuseRegions: at most 16 sources and 16 drivers");
    }
    n_sources_ = sources.size();
    n_drivers_ = drivers.size();
    std::copy(sources.begin(), sources.end(), levels_[0].sources.begin());
    std::copy(drivers.begin(), drivers.end(), levels_[0].drivers.begin());
    Visit(0, 0, nullptr, 0);
  }

 private:
  // The cursors of the region being visited at each depth.
  struct Level {
    std::array<Cursor, kMaxInputs> sources;
    std::array<Cursor, kMaxInputs> drivers;
  };

  void Visit(unsigned depth, std::uint64_t code, Node* parent, unsigned index) {
    const Level& here = levels_[depth];
    bool covered = false;
    for (std::size_t i = 0; i < n_drivers_; ++i) covered |= here.drivers[i].kind == Cursor::kUniform;
    bool uniform = true;
    for (std::size_t i = 0; i < n_sources_; ++i) {
      uniform &= here.sources[i].kind == Cursor::kNone || here.sources[i].kind == Cursor::kUniform;
    }
    Node* node = parent == nullptr
                     ? target_.getRoot()
                     : (target_.nodeChildExists(parent, index) ? target_.getNodeChild(parent, index)
                                                               : nullptr);
    if (covered && uniform) {
      Write(depth, code, parent, index, node, here);
      return;
    }
    // Descend: the target's node here must exist and have its children (a leaf is split, its
    // children keeping its value).
    if (node == nullptr) {
      node = parent == nullptr ? EnsureRoot(target_) : target_.createNodeChild(parent, index);
    } else if (!target_.nodeHasChildren(node)) {
      target_.expandNode(node);
    }
    Level& below = levels_[depth + 1];
    std::array<const MapNode*, kMaxInputs> next_source, next_driver;
    for (std::size_t i = 0; i < n_sources_; ++i) next_source[i] = here.sources[i].lo;
    for (std::size_t i = 0; i < n_drivers_; ++i) next_driver[i] = here.drivers[i].lo;
    const std::uint64_t span = MortonSpan(depth + 1);
    for (unsigned child = 0; child < 8; ++child) {
      bool driven = false;
      for (std::size_t i = 0; i < n_drivers_; ++i) {
        ChildCursor(here.drivers[i], nullptr, depth, code, child, &next_driver[i],
                    &below.drivers[i]);
        driven |= below.drivers[i].kind != Cursor::kNone;
      }
      // Sources only where a driver leads: a tree's children are not even looked at elsewhere.
      if (!driven) continue;
      for (std::size_t i = 0; i < n_sources_; ++i) {
        ChildCursor(here.sources[i], source_trees_[i], depth, code, child, &next_source[i],
                    &below.sources[i]);
      }
      Visit(depth + 1, code + child * span, node, child);
    }
    Settle(parent, index, node);
  }

  // The region's value from uniform sources (or nothing).
  void Write(unsigned depth, std::uint64_t code, Node* parent, unsigned index, Node* node,
             const Level& here) {
    std::array<float, kMaxInputs> v{};
    std::size_t n = 0;
    for (std::size_t i = 0; i < n_sources_; ++i) {
      if (here.sources[i].kind == Cursor::kUniform) v[n++] = here.sources[i].value;
    }
    if (n == 0) {
      if (node == nullptr) return;
      if (parent == nullptr) {
        target_.clear();
      } else {
        DeleteSubtree(target_, parent, index);
      }
      Changed(depth, code);
      return;
    }
    const float value = mode_ == Mode::kCopy ? v[0] : policy_.Fuse(v.data(), n);
    if (node != nullptr && !target_.nodeHasChildren(node) && node->getLogOdds() == value) return;
    if (node == nullptr) {
      node = parent == nullptr ? EnsureRoot(target_) : target_.createNodeChild(parent, index);
    } else {
      MakeLeaf(target_, node);
    }
    node->setLogOdds(value);
    Changed(depth, code);
  }

  // After its children: an empty node goes, eight equal leaves become one, an inner node holds
  // the maximum of its children.
  void Settle(Node* parent, unsigned index, Node* node) {
    if (!target_.nodeHasChildren(node)) {
      if (parent == nullptr) {
        target_.clear();
      } else {
        DeleteSubtree(target_, parent, index);
      }
      return;
    }
    if (!target_.pruneNode(node)) node->updateOccupancyChildren();
  }

  void Changed(unsigned depth, std::uint64_t code) {
    if (changed_ != nullptr) changed_->push_back({code, static_cast<std::uint8_t>(depth)});
  }

  octomap::OcTree& target_;
  Mode mode_;
  const FusionPolicy& policy_;
  std::vector<const octomap::OcTree*> source_trees_;
  std::vector<MapRegion>* changed_;
  std::size_t n_sources_ = 0, n_drivers_ = 0;
  std::array<Level, kTreeDepth + 2> levels_;
};

std::vector<Cursor> Roots(const std::vector<MergeSource>& sources,
                          std::vector<const octomap::OcTree*>* trees) {
  std::vector<Cursor> roots;
  for (const MergeSource& s : sources) {
    if (s.tree != nullptr) {
      roots.push_back(TreeCursor(*s.tree, s.tree->getRoot()));
      trees->push_back(s.tree);
    } else {
      const auto& nodes = s.grid->nodes();
      roots.push_back(GridCursor(nodes.data(), nodes.data() + nodes.size(), 0));
      trees->push_back(nullptr);
    }
  }
  return roots;
}

}  // namespace

void FuseRegions(octomap::OcTree& target, const FusionPolicy& policy,
                 const std::vector<MergeSource>& sources,
                 const std::vector<const RenderedGrid*>& drivers,
                 std::vector<MapRegion>* changed) {
  std::vector<const octomap::OcTree*> trees;
  const std::vector<Cursor> roots = Roots(sources, &trees);
  std::vector<Cursor> driver_roots;
  for (const RenderedGrid* d : drivers) {
    const auto& nodes = d->nodes();
    driver_roots.push_back(GridCursor(nodes.data(), nodes.data() + nodes.size(), 0));
  }
  Merge(target, Merge::Mode::kFuse, policy, std::move(trees), changed).Run(roots, driver_roots);
}

void CopyRegions(octomap::OcTree& target, const octomap::OcTree& source,
                 const std::vector<MapRegion>& regions, RenderedGrid* scratch) {
  RenderedGrid own(target.getResolution());
  RenderedGrid& driver = scratch != nullptr ? *scratch : own;
  driver.Clear();
  for (const MapRegion& r : regions) driver.Append({r.code, 0.0f, r.depth});
  std::vector<const octomap::OcTree*> trees;
  const std::vector<Cursor> roots = Roots({{&source, nullptr}}, &trees);
  const auto& nodes = driver.nodes();
  Merge(target, Merge::Mode::kCopy, FusionPolicy{}, std::move(trees), nullptr)
      .Run(roots, {GridCursor(nodes.data(), nodes.data() + nodes.size(), 0)});
}

bool DeleteVoxel(octomap::OcTree& tree, const octomap::OcTreeKey& key) {
  if (tree.search(key) == nullptr) return false;
  RenderedGrid voxel(tree.getResolution());
  voxel.Append({MortonOf(key), 0.0f, static_cast<std::uint8_t>(kTreeDepth)});
  FuseRegions(tree, FusionPolicy{}, {}, {&voxel});
  return true;
}

namespace {

void ForEachLeafBelow(
    const octomap::OcTree& tree, const Node* node, std::uint64_t code, unsigned depth,
    const std::function<void(const octomap::OcTreeKey&, unsigned, const octomap::OcTreeNode*)>& f) {
  if (!tree.nodeHasChildren(node)) {
    f(NodeKey(code, depth), depth, node);
    return;
  }
  for (unsigned c = 0; c < 8; ++c) {
    if (tree.nodeChildExists(node, c)) {
      ForEachLeafBelow(tree, tree.getNodeChild(node, c), code + c * MortonSpan(depth + 1),
                       depth + 1, f);
    }
  }
}

}  // namespace

void ForEachInRegion(
    const octomap::OcTree& tree, const MapRegion& region,
    const std::function<void(const octomap::OcTreeKey&, unsigned, const octomap::OcTreeNode*)>& f) {
  const Node* node = tree.getRoot();
  for (unsigned depth = 0; node != nullptr && depth < region.depth; ++depth) {
    if (!tree.nodeHasChildren(node)) break;  // a coarser leaf holds the region
    const auto child = static_cast<unsigned>((region.code >> (3 * (kTreeDepth - 1 - depth))) & 7u);
    node = tree.nodeChildExists(node, child) ? tree.getNodeChild(node, child) : nullptr;
  }
  if (node == nullptr || !tree.nodeHasChildren(node)) {
    f(NodeKey(region.code, region.depth), region.depth, node);
    return;
  }
  ForEachLeafBelow(tree, node, region.code, region.depth, f);
}

namespace {

// Full-depth keys [lo, hi] per axis of the voxels whose centres lie in a box.
struct KeyBox {
  std::array<int, 3> lo{};
  std::array<int, 3> hi{};
};

std::optional<KeyBox> KeysInBox(const Eigen::AlignedBox3d& box, double resolution_m) {
  constexpr double kOffset = 32768.0;  // OctoMap's key of the voxel at the origin
  KeyBox keys;
  for (int a = 0; a < 3; ++a) {
    // Centre of key k: (k - 32768 + 0.5) * resolution.
    const double lo = std::ceil(box.min()[a] / resolution_m - 0.5) + kOffset;
    const double hi = std::floor(box.max()[a] / resolution_m - 0.5) + kOffset;
    if (!(lo <= hi) || hi < 0.0 || lo > 65535.0) return std::nullopt;  // NaN included
    keys.lo[a] = static_cast<int>(std::max(lo, 0.0));
    keys.hi[a] = static_cast<int>(std::min(hi, 65535.0));
  }
  return keys;
}

// `node` (null: inside a coarse leaf being split) at (code, depth).
void CollectInBox(const octomap::OcTree& tree, const Node* node, bool split, std::uint64_t code,
                  unsigned depth, const KeyBox& keys, std::vector<MapRegion>* out) {
  const octomap::OcTreeKey first = KeyOfMorton(code);
  const int size = 1 << (kTreeDepth - depth);
  bool inside = true;
  for (int a = 0; a < 3; ++a) {
    const int k0 = first[a], k1 = first[a] + size - 1;
    if (k1 < keys.lo[a] || k0 > keys.hi[a]) return;  // disjoint
    inside = inside && k0 >= keys.lo[a] && k1 <= keys.hi[a];
  }
  if (inside) {
    out->push_back({code, static_cast<std::uint8_t>(depth)});
    return;
  }
  // Across a face (depth < 16: a voxel is inside or disjoint).
  const bool leaf = split || !tree.nodeHasChildren(node);
  for (unsigned c = 0; c < 8; ++c) {
    if (!leaf && !tree.nodeChildExists(node, c)) continue;
    CollectInBox(tree, leaf ? nullptr : tree.getNodeChild(node, c), leaf,
                 code + c * MortonSpan(depth + 1), depth + 1, keys, out);
  }
}

}  // namespace

std::vector<MapRegion> RegionsInBox(const octomap::OcTree& tree,
                                    const Eigen::AlignedBox3d& box_world) {
  std::vector<MapRegion> regions;
  const auto keys = KeysInBox(box_world, tree.getResolution());
  if (tree.getRoot() == nullptr || !keys) return regions;
  CollectInBox(tree, tree.getRoot(), false, 0, 0, *keys, &regions);
  return regions;
}

void NormaliseRegions(std::vector<MapRegion>* regions) {
  const auto before = [](const MapRegion& a, const MapRegion& b) {
    return a.code != b.code ? a.code < b.code : a.depth < b.depth;
  };
  // A merge reports its regions in order already: then only nested ones need to go.
  if (!std::is_sorted(regions->begin(), regions->end(), before)) {
    std::sort(regions->begin(), regions->end(), before);
  }
  std::size_t kept = 0;
  std::uint64_t covered_end = 0;
  bool any = false;
  for (const MapRegion& r : *regions) {
    if (any && r.code < covered_end) continue;  // inside the last kept region
    (*regions)[kept++] = r;
    covered_end = r.code + MortonSpan(r.depth);
    any = true;
  }
  regions->resize(kept);
}

}  // namespace fusion
