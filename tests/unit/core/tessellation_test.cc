// BeamTessellation: azimuth x elevation grid over the FOV.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "fusion/core/beam_grid.h"

namespace fusion {
namespace {

TEST(TessellationTest, CountsAndWidths) {
  const BeamTessellation t(*SensorPreset("sr3000"));
  EXPECT_EQ(t.cols(), 176);
  EXPECT_EQ(t.rows(), 144);
  EXPECT_EQ(t.beam_count(), 176u * 144u);
  EXPECT_NEAR(t.beam_width_h_rad() * 176, SensorPreset("sr3000")->fov_h_rad, 1e-12);
  EXPECT_NEAR(t.beam_width_v_rad() * 144, SensorPreset("sr3000")->fov_v_rad, 1e-12);
}

TEST(TessellationTest, DirectionMapsBackToItsBeam) {
  for (const std::string name : {"sr3000", "stoc"}) {
    const BeamTessellation t(*SensorPreset(name));
    for (std::size_t b = 0; b < t.beam_count(); b += 97) {
      const Eigen::Vector3d d = t.Direction(b);
      EXPECT_NEAR(d.norm(), 1.0, 1e-12);
      EXPECT_EQ(t.BeamOf(d), b) << name << " beam " << b;
      EXPECT_EQ(t.BeamOf(3.7 * d), b);  // range does not matter
    }
  }
}

TEST(TessellationTest, OrientationColumnZeroLeftRowZeroTop) {
  const BeamTessellation t(*SensorPreset("sr3000"));
  const Eigen::Vector3d first = t.Direction(0);
  EXPECT_LT(first.x(), 0.0);  // left
  EXPECT_LT(first.y(), 0.0);  // top (y down)
  EXPECT_GT(first.z(), 0.0);
  const Eigen::Vector3d last = t.Direction(t.beam_count() - 1);
  EXPECT_GT(last.x(), 0.0);
  EXPECT_GT(last.y(), 0.0);
  // Optical axis lands in a centre beam.
  const std::optional<std::size_t> centre = t.BeamOf(Eigen::Vector3d(0, 0, 1));
  ASSERT_TRUE(centre.has_value());
  EXPECT_EQ(*centre / 176, 72u);
  EXPECT_EQ(*centre % 176, 88u);
}

TEST(TessellationTest, OutsideFovZeroAndNonFiniteGiveNoBeam) {
  const BeamTessellation t(*SensorPreset("sr3000"));
  EXPECT_FALSE(t.BeamOf(Eigen::Vector3d(0, 0, -1)).has_value());  // behind
  EXPECT_FALSE(t.BeamOf(Eigen::Vector3d(1, 0, 1)).has_value());   // 45 deg > 23.5
  EXPECT_FALSE(t.BeamOf(Eigen::Vector3d(0, -1, 1)).has_value());  // 45 deg up > 19.5
  EXPECT_FALSE(t.BeamOf(Eigen::Vector3d(0, 0, 0)).has_value());
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  EXPECT_FALSE(t.BeamOf(Eigen::Vector3d(nan, 0, 1)).has_value());
  EXPECT_FALSE(t.BeamOf(Eigen::Vector3d(0, 0, inf)).has_value());
  // Just inside the edges.
  const double h = 0.5 * SensorPreset("sr3000")->fov_h_rad - 1e-9;
  EXPECT_EQ(t.BeamOf(Eigen::Vector3d(std::sin(h), 0, std::cos(h))).value() % 176, 175u);
  EXPECT_EQ(t.BeamOf(Eigen::Vector3d(-std::sin(h), 0, std::cos(h))).value() % 176, 0u);
  EXPECT_THROW((void)t.Direction(t.beam_count()), std::out_of_range);
}

}  // namespace
}  // namespace fusion
