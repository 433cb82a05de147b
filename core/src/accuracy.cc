#include "fusion/core/accuracy.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace fusion {

std::size_t VoxelLabels::CountOccupied() const {
  std::size_t n = 0;
  for (const auto& [key, occupied] : labels) n += occupied ? 1 : 0;
  return n;
}

AccuracyReport EvaluateMap(const octomap::OcTree& map, const VoxelLabels& labels,
                           const SurfaceDistanceFn& surface_distance,
                           const AccuracyOptions& options) {
  if (std::abs(map.getResolution() - labels.resolution_m) > 1e-9) {
    throw std::invalid_argument("EvaluateMap: map and labels differ in resolution");
  }
  AccuracyReport r;
  auto in_region = [&](const Eigen::Vector3d& c) {
    return !options.region || options.region->contains(c);
  };
  // Labelled voxels: probability from the map (0.5 where it has no node).
  double brier_sum = 0.0;
  std::size_t labelled = 0;
  std::size_t unknown = 0;
  std::size_t free_correct = 0;
  for (const auto& [key, occupied] : labels.labels) {
    const octomap::point3d c3 = map.keyToCoord(key);
    if (!in_region(Eigen::Vector3d(c3.x(), c3.y(), c3.z()))) continue;
    const octomap::OcTreeNode* node = map.search(key);
    const double p = node != nullptr ? node->getOccupancy() : 0.5;
    if (node == nullptr) ++unknown;
    ++labelled;
    const double truth = occupied ? 1.0 : 0.0;
    brier_sum += (p - truth) * (p - truth);
    if (occupied) {
      ++r.labelled_occupied;
      if (p > options.occupied_threshold) ++r.true_positives;
    } else {
      ++r.labelled_free;
      if (p < options.occupied_threshold) ++free_correct;
    }
  }
  // Predicted occupied voxels anywhere in the map (inside the region).
  double error_sum = 0.0;
  const double res = map.getResolution();
  const double holds_surface_m = 0.5 * std::sqrt(3.0) * res;  // within the voxel's half diagonal
  for (auto it = map.begin_leafs(), end = map.end_leafs(); it != end; ++it) {
    if (it->getOccupancy() <= options.occupied_threshold) continue;
    const int cells = std::max(1, static_cast<int>(std::lround(it.getSize() / res)));
    const octomap::point3d corner =
        it.getCoordinate() - octomap::point3d(1, 1, 1) * static_cast<float>(it.getSize() / 2.0);
    for (int i = 0; i < cells; ++i) {
      for (int j = 0; j < cells; ++j) {
        for (int k = 0; k < cells; ++k) {
          const Eigen::Vector3d c(corner.x() + (i + 0.5) * res, corner.y() + (j + 0.5) * res,
                                  corner.z() + (k + 0.5) * res);
          if (!in_region(c)) continue;
          ++r.predicted_occupied;
          const double e = surface_distance(c);
          const auto label = labels.labels.find(map.coordToKey(c.x(), c.y(), c.z()));
          const bool labelled = label != labels.labels.end();
          if ((labelled && label->second) || (!labelled && e <= holds_surface_m)) {
            ++r.predicted_holding_surface;
          }
          error_sum += e;
          r.max_surface_error_m = std::max(r.max_surface_error_m, e);
        }
      }
    }
  }
  r.precision =
      r.predicted_occupied > 0 ? static_cast<double>(r.true_positives) / r.predicted_occupied : 0.0;
  r.surface_precision = r.predicted_occupied > 0
                            ? static_cast<double>(r.predicted_holding_surface) / r.predicted_occupied
                            : 0.0;
  r.recall =
      r.labelled_occupied > 0 ? static_cast<double>(r.true_positives) / r.labelled_occupied : 0.0;
  r.free_accuracy = r.labelled_free > 0 ? static_cast<double>(free_correct) / r.labelled_free : 0.0;
  r.brier = labelled > 0 ? brier_sum / labelled : 0.0;
  r.unknown_fraction = labelled > 0 ? static_cast<double>(unknown) / labelled : 0.0;
  r.mean_surface_error_m = r.predicted_occupied > 0 ? error_sum / r.predicted_occupied : 0.0;
  return r;
}

}  // namespace fusion
