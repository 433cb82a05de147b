// Accuracy harness: compares an occupancy octree with ground-truth voxel
// labels.
//
// The labels come from whoever knows the truth (the scene simulator builds
// them, see fusion/sim/ground_truth.h): a voxel is labelled occupied if a
// surface passes through it and free if it is empty and some sensor ray crosses
// it before its hit (i.e. it was observable). Voxels nobody could observe are
// not labelled.
#pragma once

#include <octomap/OcTree.h>

#include <Eigen/Geometry>
#include <cstddef>
#include <functional>
#include <optional>
#include <unordered_map>

namespace fusion {

struct VoxelLabels {
  double resolution_m = 0.02;
  // true = occupied, false = free.
  std::unordered_map<octomap::OcTreeKey, bool, octomap::OcTreeKey::KeyHash> labels;
  [[nodiscard]] std::size_t CountOccupied() const;
  [[nodiscard]] std::size_t CountFree() const { return labels.size() - CountOccupied(); }
};

// Distance (metres, >= 0) from a world point to the nearest true surface.
using SurfaceDistanceFn = std::function<double(const Eigen::Vector3d& p_world)>;

struct AccuracyOptions {
  double occupied_threshold = 0.5;  // predicted occupied: p > this
  // Only map voxels / labels inside this box count (world frame); everything if
  // unset.
  std::optional<Eigen::AlignedBox3d> region;
};

struct AccuracyReport {
  std::size_t labelled_occupied = 0;
  std::size_t labelled_free = 0;
  std::size_t predicted_occupied = 0;  // map voxels with p > threshold (labelled or not)
  std::size_t true_positives = 0;      // predicted occupied and labelled occupied
  double precision = 0.0;              // true_positives / predicted_occupied
  // Predicted-occupied voxels a true surface passes through, labelled or not (the labels only
  // know the voxels some noise-free centre ray entered; a floor voxel between two rows of
  // beams holds the floor all the same).
  std::size_t predicted_holding_surface = 0;
  double surface_precision = 0.0;  // predicted_holding_surface / predicted_occupied
  double recall = 0.0;                 // true_positives / labelled_occupied
  double free_accuracy = 0.0;          // labelled free voxels with p < threshold / labelled free
  double brier = 0.0;             // mean (p - label)^2 over labelled voxels, p = 0.5 if unknown
  double unknown_fraction = 0.0;  // labelled voxels the map has no node for
  // Mean / max distance from the centres of predicted-occupied voxels to the
  // nearest surface.
  double mean_surface_error_m = 0.0;
  double max_surface_error_m = 0.0;
};

// The map must have the labels' resolution. Pruned leaves count once per voxel
// they cover.
[[nodiscard]] AccuracyReport EvaluateMap(const octomap::OcTree& map, const VoxelLabels& labels,
                                         const SurfaceDistanceFn& surface_distance,
                                         const AccuracyOptions& options = {});

}  // namespace fusion
