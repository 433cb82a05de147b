#include "fusion/core/accuracy.h"

#include <gtest/gtest.h>
#include <octomap/OcTree.h>

#include "fusion/core/local_grid.h"

namespace fusion {
namespace {

constexpr double kRes = 0.1;

// Truth: a wall of voxels at x in [1.0, 1.1), free voxels in front along x.
VoxelLabels WallLabels() {
  VoxelLabels labels;
  labels.resolution_m = kRes;
  for (int y = 0; y < 10; ++y) {
    labels.labels[KeyOfPoint({1.05, 0.05 + y * kRes, 0.05}, kRes)] = true;
    for (int x = 0; x < 10; ++x)
      labels.labels[KeyOfPoint({0.05 + x * kRes, 0.05 + y * kRes, 0.05}, kRes)] = false;
  }
  return labels;
}

double WallDistance(const Eigen::Vector3d& p) { return std::abs(p.x() - 1.05); }

void FillMap(octomap::OcTree* tree, double wall_x, float occupied, float free) {
  for (int y = 0; y < 10; ++y) {
    tree->setNodeValue(wall_x, 0.05 + y * kRes, 0.05, occupied);
    for (int x = 0; x < 10; ++x) tree->setNodeValue(0.05 + x * kRes, 0.05 + y * kRes, 0.05, free);
  }
}

TEST(Accuracy, PerfectMap) {
  octomap::OcTree tree(kRes);
  tree.setClampingThresMin(1e-6);
  tree.setClampingThresMax(1.0 - 1e-6);
  FillMap(&tree, 1.05, 20.0f, -20.0f);
  const auto r = EvaluateMap(tree, WallLabels(), WallDistance);
  EXPECT_EQ(r.labelled_occupied, 10u);
  EXPECT_EQ(r.labelled_free, 100u);
  EXPECT_DOUBLE_EQ(r.precision, 1.0);
  EXPECT_DOUBLE_EQ(r.recall, 1.0);
  EXPECT_DOUBLE_EQ(r.free_accuracy, 1.0);
  EXPECT_LT(r.brier, 1e-6);
  EXPECT_NEAR(r.mean_surface_error_m, 0.0, 1e-6);
  EXPECT_DOUBLE_EQ(r.unknown_fraction, 0.0);
}

TEST(Accuracy, EmptyMapIsUnknownEverywhere) {
  octomap::OcTree tree(kRes);
  const auto r = EvaluateMap(tree, WallLabels(), WallDistance);
  EXPECT_DOUBLE_EQ(r.brier, 0.25);
  EXPECT_DOUBLE_EQ(r.unknown_fraction, 1.0);
  EXPECT_DOUBLE_EQ(r.recall, 0.0);
  EXPECT_EQ(r.predicted_occupied, 0u);
}

TEST(Accuracy, ShiftedSurfaceShowsInErrorAndPrecision) {
  octomap::OcTree tree(kRes);
  FillMap(&tree, 1.25, 2.0f,
          -2.0f);  // wall two voxels too far (like a biased sensor)
  const auto r = EvaluateMap(tree, WallLabels(), WallDistance);
  EXPECT_EQ(r.predicted_occupied, 10u);
  EXPECT_DOUBLE_EQ(r.precision, 0.0);
  EXPECT_DOUBLE_EQ(r.recall, 0.0);
  EXPECT_NEAR(r.mean_surface_error_m, 0.2, 1e-6);
  EXPECT_NEAR(r.max_surface_error_m, 0.2, 1e-6);
  // The wall voxels themselves are unknown: 10 x 0.25 over 110 labels plus free
  // ones at 0.12.
  const double p_free = 1.0 / (1.0 + std::exp(2.0));
  EXPECT_NEAR(r.brier, (10 * 0.25 + 100 * p_free * p_free) / 110.0, 1e-6);
}

TEST(Accuracy, RegionAndResolutionChecks) {
  octomap::OcTree tree(kRes);
  FillMap(&tree, 1.05, 2.0f, -2.0f);
  AccuracyOptions options;
  options.region = Eigen::AlignedBox3d(Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(0.5, 2, 1));
  const auto r = EvaluateMap(tree, WallLabels(), WallDistance, options);
  EXPECT_EQ(r.labelled_occupied, 0u);
  EXPECT_EQ(r.labelled_free, 50u);
  octomap::OcTree other(0.05);
  EXPECT_THROW((void)EvaluateMap(other, WallLabels(), WallDistance), std::invalid_argument);
}

}  // namespace
}  // namespace fusion
