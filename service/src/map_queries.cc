#include "map_queries.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <tuple>

namespace fusion::service {
namespace {

constexpr std::size_t kStopCheckEvery = 4096;

bool KeyLess(const octomap::OcTreeKey& a, const octomap::OcTreeKey& b) {
  return std::make_tuple(a[0], a[1], a[2]) < std::make_tuple(b[0], b[1], b[2]);
}

// Whether the node at `depth` whose iterator key is `key` (its centre) shares a voxel with the
// key box [kmin, kmax]. OctoMap's leaf_bbx_iterator also yields nodes that end one key before
// the box's minimum, so every leaf it yields is checked.
bool NodeOverlapsKeyBox(const octomap::OcTreeKey& key, unsigned depth,
                        const octomap::OcTreeKey& kmin, const octomap::OcTreeKey& kmax) {
  const unsigned half = depth >= 16 ? 0u : (32768u >> depth);
  for (int axis = 0; axis < 3; ++axis) {
    const unsigned lo = key[axis] - half;
    const unsigned hi = half == 0 ? key[axis] : key[axis] + half - 1;
    if (hi < kmin[axis] || lo > kmax[axis]) return false;
  }
  return true;
}

// Unknown voxels have no node: every key of the box in order, after the token.
bool CollectEveryKey(const octomap::OcTree& tree, const octomap::OcTreeKey& kmin,
                     const octomap::OcTreeKey& kmax, const BoxQuery& query,
                     const StateThresholds& thresholds, const std::function<bool()>& stop,
                     std::vector<BoxVoxel>* page) {
  std::size_t visited = 0;
  const std::size_t wanted = std::size_t{query.page_size} + 1;
  for (unsigned x = kmin[0]; x <= kmax[0] && page->size() < wanted; ++x) {
    for (unsigned y = kmin[1]; y <= kmax[1] && page->size() < wanted; ++y) {
      for (unsigned z = kmin[2]; z <= kmax[2] && page->size() < wanted; ++z) {
        const octomap::OcTreeKey k(x, y, z);
        if (++visited % kStopCheckEvery == 0 && stop()) return false;
        if (query.has_token && !KeyLess(query.after, k)) continue;
        const octomap::OcTreeNode* node = tree.search(k);
        if (query.states.count(StateOfNode(node, thresholds)) != 0) {
          page->push_back({k, tree.getTreeDepth(), node});
        }
      }
    }
  }
  return true;
}

// The leaves of the box: the page + 1 smallest keys kept in a max-heap.
bool CollectLeaves(const octomap::OcTree& tree, const octomap::OcTreeKey& kmin,
                   const octomap::OcTreeKey& kmax, const BoxQuery& query,
                   const StateThresholds& thresholds, const std::function<bool()>& stop,
                   std::vector<BoxVoxel>* page) {
  const auto less = [](const BoxVoxel& a, const BoxVoxel& b) { return KeyLess(a.key, b.key); };
  const std::size_t wanted = std::size_t{query.page_size} + 1;
  std::size_t visited = 0;
  for (auto it = tree.begin_leafs_bbx(kmin, kmax), end = tree.end_leafs_bbx(); it != end; ++it) {
    if (++visited % kStopCheckEvery == 0 && stop()) return false;
    const octomap::OcTreeKey k = it.getKey();
    if (query.has_token && !KeyLess(query.after, k)) continue;
    if (!NodeOverlapsKeyBox(k, it.getDepth(), kmin, kmax)) continue;
    if (query.states.count(StateOfNode(&*it, thresholds)) == 0) continue;
    if (page->size() == wanted && !KeyLess(k, page->front().key)) continue;
    page->push_back({k, it.getDepth(), &*it});
    std::push_heap(page->begin(), page->end(), less);
    if (page->size() > wanted) {
      std::pop_heap(page->begin(), page->end(), less);
      page->pop_back();
    }
  }
  std::sort_heap(page->begin(), page->end(), less);
  return true;
}

}  // namespace

bool KeyOf(const octomap::OcTree& tree, const Eigen::Vector3d& p, octomap::OcTreeKey* key) {
  return tree.coordToKeyChecked(
      octomap::point3d(static_cast<float>(p.x()), static_cast<float>(p.y()),
                       static_cast<float>(p.z())),
      *key);
}

double ProbabilityOf(const octomap::OcTreeNode* node) {
  return node != nullptr ? node->getOccupancy() : 0.5;
}

fusion::v1::VoxelState StateOfNode(const octomap::OcTreeNode* node,
                                   const StateThresholds& thresholds) {
  return node != nullptr ? StateOf(node->getOccupancy(), thresholds)
                         : fusion::v1::VOXEL_STATE_UNKNOWN;
}

double BoxVoxels(const fusion::v1::QueryBoxRequest& request, double resolution_m) {
  double voxels = 1.0;
  const auto axis = [&](double lo, double hi) {
    const double n = std::floor(hi / resolution_m) - std::floor(lo / resolution_m) + 1.0;
    voxels *= std::isfinite(n) && n >= 1.0 ? n : std::numeric_limits<double>::infinity();
  };
  axis(request.min().x(), request.max().x());
  axis(request.min().y(), request.max().y());
  axis(request.min().z(), request.max().z());
  return voxels;
}

bool CollectBoxPage(const octomap::OcTree& tree, const octomap::OcTreeKey& kmin,
                    const octomap::OcTreeKey& kmax, const BoxQuery& query,
                    const StateThresholds& thresholds, const std::function<bool()>& stop,
                    std::vector<BoxVoxel>* page) {
  page->reserve(std::min<std::size_t>(std::size_t{query.page_size} + 1, 1 << 16));
  return query.states.count(fusion::v1::VOXEL_STATE_UNKNOWN) != 0
             ? CollectEveryKey(tree, kmin, kmax, query, thresholds, stop, page)
             : CollectLeaves(tree, kmin, kmax, query, thresholds, stop, page);
}

}  // namespace fusion::service
