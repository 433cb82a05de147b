// BeamTessellation: azimuth x elevation grid over the FOV.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>

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

// BeamOf compares tangents against tables; BeamOfByAngles is the definition (atan2). They
// agree on every direction that is not within 1e-9 rad of a beam edge, inside and outside the
// FOV, for narrow and single-beam tessellations; a FOV of 180 degrees or more uses the angles.
TEST(TessellationTest, TangentTablesAgreeWithTheAngles) {
  SensorSpec one_column = *SensorPreset("stoc");
  one_column.cols = 1;
  one_column.rows = 3;
  SensorSpec wide = *SensorPreset("sr3000");
  wide.fov_h_rad = 4.7;  // a 270-degree scanner
  wide.cols = 540;
  for (const SensorSpec& spec : {*SensorPreset("sr3000"), *SensorPreset("stoc"), one_column, wide}) {
    const BeamTessellation t(spec);
    std::mt19937 rng(3);
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    const auto near_edge = [](double angle, double fov, int n) {
      const double w = fov / n;
      const double k = (angle + 0.5 * fov) / w;
      return std::abs(k - std::round(k)) * w < 1e-9;
    };
    int compared = 0, inside = 0;
    for (int i = 0; i < 200000; ++i) {
      // Directions in a cone a little wider than the FOV, at assorted ranges.
      const double az = 0.6 * spec.fov_h_rad * u(rng);
      const double el = 0.6 * spec.fov_v_rad * u(rng);
      const double r = 0.1 + 5.0 * (u(rng) + 1.0);
      const Eigen::Vector3d d(r * std::cos(el) * std::sin(az), -r * std::sin(el),
                              r * std::cos(el) * std::cos(az));
      if (near_edge(std::atan2(d.x(), d.z()), spec.fov_h_rad, spec.cols) ||
          near_edge(std::atan2(-d.y(), std::hypot(d.x(), d.z())), spec.fov_v_rad, spec.rows)) {
        continue;
      }
      ++compared;
      const auto fast = t.BeamOf(d);
      ASSERT_EQ(fast, t.BeamOfByAngles(d)) << spec.name << " " << d.transpose();
      inside += fast.has_value() ? 1 : 0;
    }
    EXPECT_GT(compared, 190000);
    EXPECT_GT(inside, compared / 2);       // most directions fall inside the FOV,
    EXPECT_LT(inside, compared * 9 / 10);  // and a good share outside
  }
}

}  // namespace
}  // namespace fusion
