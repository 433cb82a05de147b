// Reading the published octree for the handlers: keys inside its range, the state of a node,
// and the voxels of a QueryBox page. Internal to service/src (map_service.cc).
#pragma once

#include <octomap/OcTree.h>

#include <Eigen/Core>
#include <functional>
#include <vector>

#include "fusion/service/conversions.h"
#include "fusion/service/request_checks.h"

namespace fusion::service {

// Key of a world point if it lies inside the octree's key range.
[[nodiscard]] bool KeyOf(const octomap::OcTree& tree, const Eigen::Vector3d& p,
                         octomap::OcTreeKey* key);
[[nodiscard]] double ProbabilityOf(const octomap::OcTreeNode* node);  // 0.5 without a node
[[nodiscard]] fusion::v1::VoxelState StateOfNode(const octomap::OcTreeNode* node,
                                                 const StateThresholds& thresholds);

// Voxels of a key box at the map's resolution, +inf for a box that is not one (the handler
// refuses it): what decides whether QueryBox is a cheap call.
[[nodiscard]] double BoxVoxels(const fusion::v1::QueryBoxRequest& request, double resolution_m);

struct BoxVoxel {
  octomap::OcTreeKey key;  // the node's key (its centre at `depth`)
  unsigned depth = 0;
  const octomap::OcTreeNode* node = nullptr;  // nullptr: unknown
};

// The page_size + 1 smallest keys after query.after (when it has a token) among the voxels of
// [kmin, kmax] whose state is asked for, in key order; memory is one page whatever the box
// holds. With unknown asked for, every key of the box is visited (unknown voxels have no node);
// otherwise the leaves. `stop` is polled every few thousand voxels: false when it said stop.
[[nodiscard]] bool CollectBoxPage(const octomap::OcTree& tree, const octomap::OcTreeKey& kmin,
                                  const octomap::OcTreeKey& kmax, const BoxQuery& query,
                                  const StateThresholds& thresholds,
                                  const std::function<bool()>& stop, std::vector<BoxVoxel>* page);

}  // namespace fusion::service
