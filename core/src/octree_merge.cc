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

// Leaves are counted as OcTree::getNumLeafNodes counts them: a node without children is one,
// whether or not it still has an (empty) child array.

// Deletes child `i` of `parent` with its whole subtree. Returns the leaves it held.
std::size_t DeleteSubtree(octomap::OcTree& tree, Node* parent, unsigned i) {
  Node* node = tree.getNodeChild(parent, i);
  std::size_t leaves = 0;
  if (Access::HasChildArray(node)) {
    for (unsigned j = 0; j < 8; ++j) {
      if (tree.nodeChildExists(node, j)) leaves += DeleteSubtree(tree, node, j);
    }
    Access::ReleaseEmptyChildArray(node);
  }
  tree.deleteNodeChild(parent, i);
  return std::max<std::size_t>(leaves, 1);
}

// Deletes every child of `node`, which becomes a leaf. Returns the leaves its children held.
std::size_t MakeLeaf(octomap::OcTree& tree, Node* node) {
  if (!Access::HasChildArray(node)) return 0;
  std::size_t leaves = 0;
  for (unsigned j = 0; j < 8; ++j) {
    if (tree.nodeChildExists(node, j)) leaves += DeleteSubtree(tree, node, j);
  }
  Access::ReleaseEmptyChildArray(node);
  return leaves;
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

// The nodes [lo, hi) of a region at `depth` (a few) fill it with one value (a render decides
// a block's voxels one by one where its parent block was mixed). They are disjoint and inside
// the region: they fill it when their volumes add up to its volume.
bool FillsWithOneValue(const MapNode* lo, const MapNode* hi, unsigned depth) {
  if (hi - lo > 64) return false;
  std::uint64_t volume = 0;
  for (const MapNode* n = lo; n != hi; ++n) {
    if (n->log_odds != lo->log_odds) return false;
    volume += MortonSpan(n->depth);
  }
  return volume == MortonSpan(depth);
}

Cursor GridCursor(const MapNode* lo, const MapNode* hi, unsigned depth) {
  Cursor c;
  if (lo == hi) return c;
  // A node covering the whole region (the only one in it), or a few nodes of one value filling
  // it: the region is written whole, not as leaves the target would prune into one.
  if (lo->depth <= depth || FillsWithOneValue(lo, hi, depth)) {
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

// One merge: the target, the sources and drivers, and how opinions become a value. With a
// catch-up (a reference tree and the regions where the target lags behind it), the target is
// first brought to the reference in those regions, in the same walk: where a driver leads the
// fused value is written at once, elsewhere in the lagging regions the reference's content is
// copied; a region counts as changed when its fused value differs from the reference's.
class Merge {
 public:
  static constexpr std::size_t kMaxInputs = 16;

  Merge(octomap::OcTree& target, const FusionPolicy& policy,
        std::vector<const octomap::OcTree*> source_trees, std::vector<MapRegion>* changed)
      : target_(target),
        policy_(policy),
        source_trees_(std::move(source_trees)),
        changed_(changed) {}

  // How the target's leaf count changed (OcTree::getNumLeafNodes after less before).
  [[nodiscard]] std::int64_t leaves_added() const { return leaves_; }

  // reference: null, or the tree the target catches up with in the regions `lag` holds.
  void Run(const std::vector<Cursor>& sources, const std::vector<Cursor>& drivers,
           const octomap::OcTree* reference = nullptr, const Cursor& lag = {}) {
    if (sources.size() > kMaxInputs || drivers.size() > kMaxInputs) {
      throw std::invalid_argument("FuseRegions: at most 16 sources and 16 drivers");
    }
    n_sources_ = sources.size();
    n_drivers_ = drivers.size();
    std::copy(sources.begin(), sources.end(), levels_[0].sources.begin());
    std::copy(drivers.begin(), drivers.end(), levels_[0].drivers.begin());
    reference_ = reference;
    if (reference_ != nullptr) {
      levels_[0].lag = lag;
      levels_[0].ref = TreeCursor(*reference_, reference_->getRoot());
    }
    Visit(0, 0, nullptr, 0);
  }

 private:
  // The cursors of the region being visited at each depth.
  struct Level {
    std::array<Cursor, kMaxInputs> sources;
    std::array<Cursor, kMaxInputs> drivers;
    Cursor lag, ref;  // with a catch-up: the lagging regions, the reference's content
  };

  void Visit(unsigned depth, std::uint64_t code, Node* parent, unsigned index) {
    const Level& here = levels_[depth];
    bool covered = false, driven = false;
    for (std::size_t i = 0; i < n_drivers_; ++i) {
      covered |= here.drivers[i].kind == Cursor::kUniform;
      driven |= here.drivers[i].kind != Cursor::kNone;
    }
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
    if (!driven && here.lag.kind == Cursor::kUniform && here.ref.kind != Cursor::kTree) {
      Copy(parent, index, node, here.ref);  // catching up only
      return;
    }
    // Descend: the target's node here must exist and have its children (a leaf is split, its
    // children keeping its value).
    if (node == nullptr) {
      node = Create(parent, index);
    } else if (!target_.nodeHasChildren(node)) {
      target_.expandNode(node);
      leaves_ += 7;
    }
    Level& below = levels_[depth + 1];
    std::array<const MapNode*, kMaxInputs> next_source, next_driver;
    for (std::size_t i = 0; i < n_sources_; ++i) next_source[i] = here.sources[i].lo;
    for (std::size_t i = 0; i < n_drivers_; ++i) next_driver[i] = here.drivers[i].lo;
    const MapNode* next_lag = here.lag.lo;
    const std::uint64_t span = MortonSpan(depth + 1);
    for (unsigned child = 0; child < 8; ++child) {
      bool child_driven = false;
      for (std::size_t i = 0; i < n_drivers_; ++i) {
        ChildCursor(here.drivers[i], nullptr, depth, code, child, &next_driver[i],
                    &below.drivers[i]);
        child_driven |= below.drivers[i].kind != Cursor::kNone;
      }
      ChildCursor(here.lag, nullptr, depth, code, child, &next_lag, &below.lag);
      const bool lagging = below.lag.kind != Cursor::kNone;
      if (!child_driven && !lagging) continue;
      // Sources only where a driver leads: a tree's children are not even looked at elsewhere.
      if (child_driven) {
        for (std::size_t i = 0; i < n_sources_; ++i) {
          ChildCursor(here.sources[i], source_trees_[i], depth, code, child, &next_source[i],
                      &below.sources[i]);
        }
      }
      // Outside the lagging regions the target holds what the reference holds.
      if (lagging) ChildCursor(here.ref, reference_, depth, code, child, nullptr, &below.ref);
      Visit(depth + 1, code + child * span, node, child);
    }
    Settle(parent, index, node);
  }

  // The region's value from uniform sources (or nothing). Changed: against the reference where
  // the target lags behind it, else against what the target held.
  void Write(unsigned depth, std::uint64_t code, Node* parent, unsigned index, Node* node,
             const Level& here) {
    std::array<float, kMaxInputs> v{};
    std::size_t n = 0;
    for (std::size_t i = 0; i < n_sources_; ++i) {
      if (here.sources[i].kind == Cursor::kUniform) v[n++] = here.sources[i].value;
    }
    const bool lagging = here.lag.kind != Cursor::kNone;
    if (n == 0) {
      const bool had = lagging ? here.ref.kind != Cursor::kNone : node != nullptr;
      if (node != nullptr) Remove(parent, index);
      if (had) Changed(depth, code);
      return;
    }
    const float value = policy_.Fuse(v.data(), n);
    const bool held = node != nullptr && !target_.nodeHasChildren(node) && node->getLogOdds() == value;
    const bool same =
        lagging ? here.ref.kind == Cursor::kUniform && here.ref.value == value : held;
    if (!held) SetLeaf(parent, index, node, value);
    if (!same) Changed(depth, code);
  }

  // The reference's content of a lagging region (uniform or nothing) into the target.
  void Copy(Node* parent, unsigned index, Node* node, const Cursor& ref) {
    if (ref.kind == Cursor::kNone) {
      if (node != nullptr) Remove(parent, index);
      return;
    }
    if (node != nullptr && !target_.nodeHasChildren(node) && node->getLogOdds() == ref.value) return;
    SetLeaf(parent, index, node, ref.value);
  }

  void Remove(Node* parent, unsigned index) {
    if (parent == nullptr) {
      leaves_ -= static_cast<std::int64_t>(target_.getNumLeafNodes());
      target_.clear();
      return;
    }
    leaves_ -= static_cast<std::int64_t>(DeleteSubtree(target_, parent, index));
    if (!target_.nodeHasChildren(parent)) ++leaves_;  // its last child: the parent is a leaf now
  }

  // A new leaf at child `index` of `parent` (null: the root of an empty tree).
  Node* Create(Node* parent, unsigned index) {
    if (parent == nullptr) {
      ++leaves_;
      return EnsureRoot(target_);
    }
    if (target_.nodeHasChildren(parent)) ++leaves_;  // else the parent was the leaf
    return target_.createNodeChild(parent, index);
  }

  void SetLeaf(Node* parent, unsigned index, Node* node, float value) {
    if (node == nullptr) {
      node = Create(parent, index);
    } else if (target_.nodeHasChildren(node)) {
      leaves_ += 1 - static_cast<std::int64_t>(MakeLeaf(target_, node));
    } else {
      MakeLeaf(target_, node);  // an empty child array
    }
    node->setLogOdds(value);
  }

  // After its children: an empty node goes, eight equal leaves become one, an inner node holds
  // the maximum of its children.
  void Settle(Node* parent, unsigned index, Node* node) {
    if (!target_.nodeHasChildren(node)) {
      Remove(parent, index);
      return;
    }
    if (target_.pruneNode(node)) {
      leaves_ -= 7;
    } else {
      node->updateOccupancyChildren();
    }
  }

  void Changed(unsigned depth, std::uint64_t code) {
    if (changed_ != nullptr) changed_->push_back({code, static_cast<std::uint8_t>(depth)});
  }

  octomap::OcTree& target_;
  const FusionPolicy& policy_;
  std::vector<const octomap::OcTree*> source_trees_;
  std::vector<MapRegion>* changed_;
  const octomap::OcTree* reference_ = nullptr;
  std::size_t n_sources_ = 0, n_drivers_ = 0;
  std::int64_t leaves_ = 0;
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

// The regions as a driver (in *grid's memory).
Cursor RegionsCursor(const std::vector<MapRegion>& regions, RenderedGrid* grid) {
  grid->Clear();
  for (const MapRegion& r : regions) grid->Append({r.code, 0.0f, r.depth});
  const auto& nodes = grid->nodes();
  return GridCursor(nodes.data(), nodes.data() + nodes.size(), 0);
}

}  // namespace

void FuseRegions(octomap::OcTree& target, const FusionPolicy& policy,
                 const std::vector<MergeSource>& sources,
                 const std::vector<const RenderedGrid*>& drivers,
                 std::vector<MapRegion>* changed, const CatchUp* catch_up,
                 std::int64_t* leaves_added) {
  std::vector<const octomap::OcTree*> trees;
  const std::vector<Cursor> roots = Roots(sources, &trees);
  std::vector<Cursor> driver_roots;
  for (const RenderedGrid* d : drivers) {
    const auto& nodes = d->nodes();
    driver_roots.push_back(GridCursor(nodes.data(), nodes.data() + nodes.size(), 0));
  }
  Merge merge(target, policy, std::move(trees), changed);
  if (catch_up == nullptr || catch_up->reference == nullptr || catch_up->regions == nullptr) {
    merge.Run(roots, driver_roots);
  } else {
    RenderedGrid own(target.getResolution());
    RenderedGrid* buffer = catch_up->buffer != nullptr ? catch_up->buffer : &own;
    merge.Run(roots, driver_roots, catch_up->reference, RegionsCursor(*catch_up->regions, buffer));
  }
  if (leaves_added != nullptr) *leaves_added += merge.leaves_added();
}

void CopyRegions(octomap::OcTree& target, const octomap::OcTree& source,
                 const std::vector<MapRegion>& regions, RenderedGrid* scratch,
                 std::int64_t* leaves_added) {
  const CatchUp catch_up{&source, &regions, scratch};
  FuseRegions(target, FusionPolicy{}, {}, {}, nullptr, &catch_up, leaves_added);
}

std::size_t TreeMemoryBytes(const octomap::OcTree& tree, std::size_t leaves) {
  using Base = octomap::OcTreeBaseImpl<octomap::OcTreeNode, octomap::AbstractOccupancyOcTree>;
  const std::size_t nodes = tree.size();
  return sizeof(Base) + tree.memoryUsageNode() * nodes +
         (nodes - std::min(leaves, nodes)) * sizeof(octomap::OcTreeNode* [8]);
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
