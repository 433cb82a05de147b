// The voxel rule on one beam with a wide first-hit distribution (issue 11, "fat surfaces";
// docs/mapping.md, "From first-hit mass to evidence"): a surface is occupied where the beam
// more likely stops than passes, not over the whole band of its noise; behind the mass, where
// Eq. 8's hazard tends to 1 but the beam hardly ever gets, nothing is claimed.
#include <gtest/gtest.h>

#include <cmath>
#include <optional>
#include <vector>

#include "fusion/core/world_map.h"

namespace fusion {
namespace {

constexpr double kVoxelM = 0.02;

// Occupancy along the optical axis (every voxel from 1 m to 3 m) after `readings` readings at
// reading_m (one period; default 2.01 m, a voxel's centre) of a laser whose reading noise is
// sigma_m at every range.
std::vector<std::optional<double>> AlongTheAxis(double sigma_m, int readings,
                                                std::vector<double>* at_m,
                                                double reading_m = 2.01) {
  WorldMapOptions options;
  options.resolution_m = kVoxelM;
  options.render.resolution_m = kVoxelM;
  WorldMap map(options);
  SensorSpec laser = *SensorPreset("laser_3d");
  laser.q_sigma = {0.0, 0.0, sigma_m};
  EXPECT_EQ(map.AddSensor("laser", laser), MapStatus::kOk);
  const float point[3] = {0.0f, 0.0f, static_cast<float>(reading_m)};
  for (int i = 0; i < readings; ++i) {
    EXPECT_EQ(map.Integrate("laser", Eigen::Isometry3d::Identity(), point, 1), MapStatus::kOk);
  }
  EXPECT_EQ(map.Render("laser"), MapStatus::kOk);
  std::vector<std::optional<double>> out;
  at_m->clear();
  for (double z = 1.01; z < 3.0; z += kVoxelM) {
    at_m->push_back(z);
    out.push_back(map.Occupancy(Eigen::Vector3d(0.0, 0.0, z)));
  }
  return out;
}

bool Occupied(const std::optional<double>& p) { return p && *p >= 0.55; }

// Common to every case: the beam clears well in front of the noise band, and nothing three
// sigma behind the reading (where the beam hardly ever gets) is occupied.
void ExpectClearInFrontAndNothingBehind(double sigma_m, const std::vector<double>& at,
                                        const std::vector<std::optional<double>>& p) {
  ASSERT_TRUE(p[10].has_value());  // 1.21 m
  EXPECT_LE(*p[10], 0.45) << "sigma " << sigma_m;
  for (std::size_t i = 0; i < at.size(); ++i) {
    if (at[i] > 2.01 + 3.0 * sigma_m) EXPECT_FALSE(Occupied(p[i])) << sigma_m << " " << at[i];
  }
}

TEST(VoxelRuleTest, ASharpReadingIsOccupiedAtItsVoxelOnly) {
  std::vector<double> at;
  const auto p = AlongTheAxis(0.01, 1, &at);
  int occupied = 0;
  for (std::size_t i = 0; i < at.size(); ++i) {
    if (!Occupied(p[i])) continue;
    ++occupied;
    EXPECT_LE(std::abs(at[i] - 2.01), kVoxelM + 1e-6) << at[i];
  }
  EXPECT_GE(occupied, 1);
  ExpectClearInFrontAndNothingBehind(0.01, at, p);
}

// One reading with sigma twice or four times the voxel cannot say which voxel holds the
// surface: the band stays unknown (near 0.5), not occupied (the old rule occupied the whole
// +-3 sigma band and put its far end at the clamp).
TEST(VoxelRuleTest, AWideReadingLeavesItsBandUncertain) {
  for (const double sigma_m : {0.04, 0.08}) {
    std::vector<double> at;
    const auto p = AlongTheAxis(sigma_m, 1, &at);
    for (std::size_t i = 0; i < at.size(); ++i) {
      EXPECT_FALSE(Occupied(p[i])) << "sigma " << sigma_m << " at " << at[i];
      if (std::abs(at[i] - 2.01) <= sigma_m && p[i]) {
        EXPECT_GT(*p[i], 0.45) << "sigma " << sigma_m << " at " << at[i];
      }
    }
    ExpectClearInFrontAndNothingBehind(sigma_m, at, p);
  }
}

// Readings that agree concentrate the first-hit mass (sigma / sqrt(n)): the surface appears,
// thin, where they put it.
TEST(VoxelRuleTest, AgreeingReadingsMakeAWideSurfaceThin) {
  const double sigma_m = 0.04;
  std::vector<double> at;
  const auto p = AlongTheAxis(sigma_m, 16, &at);
  int occupied = 0;
  for (std::size_t i = 0; i < at.size(); ++i) {
    if (!Occupied(p[i])) continue;
    ++occupied;
    EXPECT_LE(std::abs(at[i] - 2.01), 2.0 * kVoxelM + 1e-6) << at[i];
  }
  EXPECT_GE(occupied, 1);
  EXPECT_LE(occupied, 3);
  ExpectClearInFrontAndNothingBehind(sigma_m, at, p);
}

// A reading 4 mm in front of a voxel boundary (2.00 m) with sigma 8 mm puts two thirds of its
// first-hit mass in the voxel in front and a third behind. The voxel behind is where Eq. 8's
// hazard tends to 1 (the beam that gets there stops there): before, it took more occupied
// evidence than the voxel holding most of the mass and both came out occupied, the surface a
// voxel thick behind the reading. Only the voxel holding most of the mass is occupied.
TEST(VoxelRuleTest, OnlyTheVoxelHoldingMostOfTheMassIsOccupied) {
  for (const int readings : {1, 4}) {
    std::vector<double> at;
    const auto p = AlongTheAxis(0.008, readings, &at, 1.996);
    for (std::size_t i = 0; i < at.size(); ++i) {
      const bool in_front = std::abs(at[i] - 1.99) < 1e-6;  // the voxel [1.98, 2.00)
      EXPECT_EQ(Occupied(p[i]), in_front) << readings << " readings, at " << at[i];
    }
    ExpectClearInFrontAndNothingBehind(0.008, at, p);
  }
}

}  // namespace
}  // namespace fusion
