#include "fusion/core/local_grid.h"

#include <gtest/gtest.h>
#include <octomap/OcTree.h>

#include <cmath>
#include <vector>

#include "fusion/core/fusion_rules.h"

namespace fusion {
namespace {

constexpr double kRes = 0.02;

// One narrow beam along the optical z axis.
SensorSpec PencilSpec() {
  SensorSpec spec;
  spec.name = "pencil";
  spec.r_min_m = 0.2;
  spec.r_max_m = 2.0;
  spec.fov_h_rad = 0.002;
  spec.fov_v_rad = 0.002;
  spec.cols = 1;
  spec.rows = 1;
  spec.q_mu = {0.0, 1.0, 0.0};
  spec.q_sigma = {0.0, 0.0, 0.004};
  return spec;
}

BeamGridOptions GridOptions() {
  BeamGridOptions options;
  options.cell_size_m = 0.001;
  options.prior_reference_length_m = kRes;
  return options;
}

octomap::OcTreeKey KeyAtZ(double z) { return KeyOfPoint(Eigen::Vector3d(0.0001, 0.0001, z), kRes); }

TEST(LocalGrid, KeysMatchOctoMap) {
  octomap::OcTree tree(kRes);
  for (const Eigen::Vector3d& p :
       {Eigen::Vector3d(0.0, 0.0, 0.0), Eigen::Vector3d(-0.01, 1.33, -7.2),
        Eigen::Vector3d(12.345, -0.019, 0.021)}) {
    const auto key = KeyOfPoint(p, kRes);
    EXPECT_EQ(key, tree.coordToKey(p.x(), p.y(), p.z()));
    const octomap::point3d c = tree.keyToCoord(key);
    EXPECT_TRUE(KeyCenter(key, kRes).isApprox(Eigen::Vector3d(c.x(), c.y(), c.z()), 1e-6));
  }
}

TEST(LocalGrid, CombineModes) {
  const octomap::OcTreeKey key(1, 2, 3);
  for (VoxelCombine combine : {VoxelCombine::kWeightedMeanLogOdds, VoxelCombine::kMaxLogOdds,
                               VoxelCombine::kIndependentPool}) {
    LocalGrid grid(kRes, combine);
    EXPECT_FALSE(grid.Probability(key).has_value());
    grid.AddEvidence(key, 2.0, 0.02);
    grid.AddEvidence(key, -1.0, 0.01);
    ASSERT_EQ(grid.size(), 1u);
    const double l = *grid.LogOddsOf(key);
    switch (combine) {
      case VoxelCombine::kWeightedMeanLogOdds:
        EXPECT_NEAR(l, (2.0 * 0.02 - 0.01) / 0.03, 1e-6);
        break;
      case VoxelCombine::kMaxLogOdds:
        EXPECT_NEAR(l, 2.0, 1e-6);
        break;
      case VoxelCombine::kIndependentPool:
        EXPECT_NEAR(l, 1.0, 1e-6);
        break;
    }
  }
}

TEST(LocalGrid, ManyKeysSurviveGrowth) {
  LocalGrid grid(kRes);
  for (int i = 0; i < 5000; ++i) {
    grid.AddEvidence(octomap::OcTreeKey(i % 100, i / 100, 7), 0.001 * i, 1.0);
  }
  EXPECT_EQ(grid.size(), 5000u);
  EXPECT_NEAR(*grid.LogOddsOf(octomap::OcTreeKey(17, 42, 7)), 0.001 * (42 * 100 + 17), 1e-5);
  grid.Clear();
  EXPECT_TRUE(grid.empty());
}

TEST(LocalGrid, UntouchedGridRendersNothing) {
  BeamGrid grid(PencilSpec(), GridOptions());
  RenderStats stats;
  const LocalGrid local = RenderBeamGrid(grid, Eigen::Isometry3d::Identity(), {}, &stats);
  EXPECT_TRUE(local.empty());
  EXPECT_EQ(stats.beams_untouched, 1u);
}

TEST(LocalGrid, PencilBeamFreeBeforeOccupiedAtUnknownBehind) {
  BeamGrid grid(PencilSpec(), GridOptions());
  for (int i = 0; i < 10; ++i) grid.Update(0, {Reading::Kind::kRange, 1.01});
  RenderStats stats;
  const LocalGrid local = RenderBeamGrid(grid, Eigen::Isometry3d::Identity(), {}, &stats);
  EXPECT_EQ(stats.beams_rendered, 1u);
  // Nothing below r_min.
  EXPECT_FALSE(local.Probability(KeyAtZ(0.15)).has_value());
  // Free space in front.
  for (double z = 0.25; z < 0.95; z += 0.05) {
    const auto p = local.Probability(KeyAtZ(z));
    ASSERT_TRUE(p.has_value()) << z;
    EXPECT_LT(*p, 0.1) << z;
  }
  // The surface voxel [1.00, 1.02).
  ASSERT_TRUE(local.Probability(KeyAtZ(1.01)).has_value());
  EXPECT_GT(*local.Probability(KeyAtZ(1.01)), 0.9);
  // Behind the surface: the ray stopped, unknown.
  EXPECT_FALSE(local.Probability(KeyAtZ(1.2)).has_value());
  EXPECT_FALSE(local.Probability(KeyAtZ(1.9)).has_value());
}

TEST(LocalGrid, VoxelValueIsTheIntervalOccupancyOfItsCrossing) {
  // Oracle: 1 - S(b1) / S(b0) from the full p(B) vector (slow and obvious).
  BeamGrid grid(PencilSpec(), GridOptions());
  for (double r : {0.995, 1.003, 1.012, 0.999}) grid.Update(0, {Reading::Kind::kRange, r});
  const std::vector<double> pb = grid.FirstHitProbabilities(0);
  auto tail = [&](double range_m) {
    const auto first = static_cast<std::size_t>(std::lround(range_m / 0.001));
    double s = 0.0;
    for (std::size_t i = first; i < pb.size(); ++i) s += pb[i];
    return s;
  };
  RenderOptions options;
  options.tail_mass = 1e-12;
  const LocalGrid local = RenderBeamGrid(grid, Eigen::Isometry3d::Identity(), options);
  for (double z0 : {0.96, 0.98, 1.00, 1.02}) {
    const double s0 = tail(z0);
    const double s1 = tail(z0 + kRes);
    if (s0 < 1e-9) continue;
    const double expected = std::clamp(1.0 - s1 / s0, 1e-5, 1.0 - 1e-5);
    const auto p = local.Probability(KeyAtZ(z0 + kRes / 2));
    ASSERT_TRUE(p.has_value()) << z0;
    // Full crossing: prior of 20 cells is 0.5, so the evidence is the plain
    // log-odds.
    EXPECT_NEAR(LogOdds(std::clamp(*p, 1e-5, 1.0 - 1e-5)), LogOdds(expected), 0.02) << z0;
  }
}

TEST(LocalGrid, MountOffsetMovesTheSurface) {
  BeamGrid grid(PencilSpec(), GridOptions());
  for (int i = 0; i < 10; ++i) grid.Update(0, {Reading::Kind::kRange, 1.01});
  Eigen::Isometry3d T_world_sensor = Eigen::Isometry3d::Identity();
  T_world_sensor.translation() = Eigen::Vector3d(0.5, -0.3, 0.2);
  const LocalGrid local = RenderBeamGrid(grid, T_world_sensor, {});
  const auto p = local.Probability(KeyOfPoint(Eigen::Vector3d(0.5001, -0.2999, 1.21), kRes));
  ASSERT_TRUE(p.has_value());
  EXPECT_GT(*p, 0.9);
  EXPECT_FALSE(local.Probability(KeyAtZ(1.01)).has_value());
}

TEST(LocalGrid, BeyondRangeClearsTheWholeBeam) {
  BeamGrid grid(PencilSpec(), GridOptions());
  for (int i = 0; i < 5; ++i) grid.Update(0, {Reading::Kind::kBeyondRange, 0.0});
  const LocalGrid local = RenderBeamGrid(grid, Eigen::Isometry3d::Identity(), {});
  for (double z = 0.25; z < 1.98; z += 0.1) {
    const auto p = local.Probability(KeyAtZ(z));
    ASSERT_TRUE(p.has_value()) << z;
    EXPECT_LT(*p, 0.5) << z;
  }
}

TEST(LocalGrid, WideBeamCoversItsSector) {
  SensorSpec spec = PencilSpec();
  spec.fov_h_rad = 0.1;  // 5.7 degrees: 10 cm wide at 1 m
  spec.fov_v_rad = 0.1;
  BeamGrid grid(spec, GridOptions());
  for (int i = 0; i < 10; ++i) grid.Update(0, {Reading::Kind::kRange, 1.01});
  RenderStats stats;
  const LocalGrid local = RenderBeamGrid(grid, Eigen::Isometry3d::Identity(), {}, &stats);
  EXPECT_EQ(stats.rays_traced, 1u + 9u);  // centre ray, then 3 x 3 sub-rays
  // Sub-rays at +-1/3 of the half width: about 3.3 cm off axis at 1 m.
  const auto p = local.Probability(KeyOfPoint(Eigen::Vector3d(0.034, 0.0001, 1.01), kRes));
  ASSERT_TRUE(p.has_value());
  EXPECT_GT(*p, 0.9);
}

// Threads split the beams and merge their grids: the same voxels with the same values (max:
// exactly; mean and pool: up to float rounding of the sums), and the same counts.
TEST(LocalGrid, ThreadsRenderTheSameGrid) {
  SensorSpec spec = PencilSpec();
  spec.fov_h_rad = 0.6;
  spec.fov_v_rad = 0.5;
  spec.cols = 24;
  spec.rows = 21;
  BeamGrid grid(spec, GridOptions());
  for (int i = 0; i < 4; ++i) {
    for (std::size_t b = 0; b < grid.beam_count(); ++b) {
      if (b % 7 == 3) continue;  // untouched beams
      const Reading reading = b % 5 == 0 ? Reading{Reading::Kind::kBeyondRange, 0.0}
                                         : Reading{Reading::Kind::kRange, 0.8 + 0.002 * (b % 50)};
      grid.Update(b, reading);
    }
  }
  const Eigen::Isometry3d T_world_sensor =
      Eigen::Translation3d(0.1, -0.2, 0.3) * Eigen::AngleAxisd(0.4, Eigen::Vector3d::UnitY());
  for (const VoxelCombine combine : {VoxelCombine::kMaxLogOdds, VoxelCombine::kWeightedMeanLogOdds,
                                     VoxelCombine::kIndependentPool}) {
    RenderOptions options;
    options.combine = combine;
    RenderStats one_stats;
    const LocalGrid one = RenderBeamGrid(grid, T_world_sensor, options, &one_stats);
    for (const unsigned threads : {2u, 3u}) {
      options.threads = threads;
      RenderStats many_stats;
      const LocalGrid many = RenderBeamGrid(grid, T_world_sensor, options, &many_stats);
      ASSERT_GT(one.size(), 1000u);
      ASSERT_EQ(many.size(), one.size());
      EXPECT_EQ(many_stats.beams_rendered, one_stats.beams_rendered);
      EXPECT_EQ(many_stats.beams_untouched, one_stats.beams_untouched);
      EXPECT_EQ(many_stats.rays_traced, one_stats.rays_traced);
      EXPECT_EQ(many_stats.segments, one_stats.segments);
      one.ForEachLogOdds([&](const octomap::OcTreeKey& key, float l) {
        const auto m = many.LogOddsOf(key);
        ASSERT_TRUE(m.has_value());
        if (combine == VoxelCombine::kMaxLogOdds) {
          EXPECT_EQ(static_cast<float>(*m), l);
        } else {
          EXPECT_NEAR(*m, l, 1e-4 * (1.0 + std::abs(l)));
        }
      });
    }
  }
}

}  // namespace
}  // namespace fusion
