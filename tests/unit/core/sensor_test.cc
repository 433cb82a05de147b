// Sensor presets: paper Tables I and II, exactly.
#include "fusion/core/sensor.h"

#include <gtest/gtest.h>

#include <cmath>

namespace fusion {
namespace {

constexpr double kDeg = 3.14159265358979323846 / 180.0;

TEST(SensorPresetTest, Sr3000MatchesTablesOneAndTwo) {
  const std::optional<SensorSpec> s = SensorPreset("sr3000");
  ASSERT_TRUE(s.has_value());
  EXPECT_EQ(s->model, ForwardModelKind::kPaper3d);
  EXPECT_DOUBLE_EQ(s->r_min_m, 0.600);
  EXPECT_DOUBLE_EQ(s->r_max_m, 7.500);
  EXPECT_DOUBLE_EQ(s->fov_h_rad, 47.0 * kDeg);
  EXPECT_DOUBLE_EQ(s->fov_v_rad, 39.0 * kDeg);
  EXPECT_EQ(s->cols, 176);
  EXPECT_EQ(s->rows, 144);
  EXPECT_FALSE(s->range_unbounded);
  // Table II in mm, converted: a2 per mm -> * 1000, a0 mm -> / 1000.
  EXPECT_DOUBLE_EQ(s->q_mu.a2, 0.0);
  EXPECT_DOUBLE_EQ(s->q_mu.a1, 1.0);
  EXPECT_DOUBLE_EQ(s->q_mu.a0, 0.0);
  EXPECT_DOUBLE_EQ(s->q_sigma.a2, -0.243897e-6 * 1000.0);
  EXPECT_DOUBLE_EQ(s->q_sigma.a1, 0.486625e-2);
  EXPECT_DOUBLE_EQ(s->q_sigma.a0, -0.7691149 / 1000.0);
}

TEST(SensorPresetTest, StocMatchesTablesOneAndTwo) {
  const std::optional<SensorSpec> s = SensorPreset("stoc");
  ASSERT_TRUE(s.has_value());
  EXPECT_DOUBLE_EQ(s->r_min_m, 0.686);
  EXPECT_DOUBLE_EQ(s->r_max_m, 5.0);  // beam length for r_max = inf
  EXPECT_TRUE(s->range_unbounded);
  EXPECT_DOUBLE_EQ(s->fov_h_rad, 65.5 * kDeg);
  EXPECT_DOUBLE_EQ(s->fov_v_rad, 51.5 * kDeg);
  EXPECT_EQ(s->cols, 640);
  EXPECT_EQ(s->rows, 480);
  EXPECT_DOUBLE_EQ(s->q_mu.a2, 0.0);
  EXPECT_DOUBLE_EQ(s->q_mu.a1, 1.150204);
  EXPECT_DOUBLE_EQ(s->q_mu.a0, -78.158607 / 1000.0);
  EXPECT_DOUBLE_EQ(s->q_sigma.a2, 0.947909e-5 * 1000.0);
  EXPECT_DOUBLE_EQ(s->q_sigma.a1, -0.178817e-1);
  EXPECT_DOUBLE_EQ(s->q_sigma.a0, 11.186380 / 1000.0);
}

// Table II evaluated in mm (as printed in the paper) against the metre polynomials.
TEST(SensorPresetTest, TableTwoPolynomialsAtSeveralRanges) {
  const SensorSpec sr = *SensorPreset("sr3000");
  const SensorSpec sc = *SensorPreset("stoc");
  for (double r_mm : {700.0, 1500.0, 3000.0, 5000.0, 7000.0}) {
    const double r_m = r_mm / 1000.0;
    const double sr_sigma_mm = -0.243897e-6 * r_mm * r_mm + 0.486625e-2 * r_mm - 0.7691149;
    const double sc_mu_mm = 1.150204 * r_mm - 78.158607;
    const double sc_sigma_mm = 0.947909e-5 * r_mm * r_mm - 0.178817e-1 * r_mm + 11.186380;
    EXPECT_NEAR(sr.q_mu(r_m), r_m, 1e-12) << r_mm;
    EXPECT_NEAR(sr.q_sigma(r_m) * 1000.0, sr_sigma_mm, 1e-9) << r_mm;
    EXPECT_NEAR(sc.q_mu(r_m) * 1000.0, sc_mu_mm, 1e-9) << r_mm;
    EXPECT_NEAR(sc.q_sigma(r_m) * 1000.0, sc_sigma_mm, 1e-9) << r_mm;
  }
  // The two figures quoted in the issue.
  EXPECT_NEAR(sr.q_sigma(3.0) * 1000.0, -0.243897e-6 * 9e6 + 0.486625e-2 * 3000 - 0.7691149, 1e-9);
  EXPECT_NEAR(sr.q_sigma(3.0) * 1000.0, 11.63456, 1e-5);
  EXPECT_NEAR(sc.q_mu(3.0) * 1000.0, 3372.45, 0.01);
}

TEST(SensorPresetTest, NamesAndUnknown) {
  EXPECT_EQ(SensorPresetNames(),
            (std::vector<std::string>{"sr3000", "stoc", "kinect_v1", "laser_3d"}));
  EXPECT_FALSE(SensorPreset("kinect").has_value());
  EXPECT_FALSE(SensorPreset("").has_value());
  for (const std::string& name : SensorPresetNames()) {
    EXPECT_EQ(ValidateSensorSpec(*SensorPreset(name)), "") << name;
  }
}

TEST(SensorPresetTest, FromMillimetres) {
  const Polynomial2 q = Polynomial2::FromMillimetres(2e-6, 0.5, 30.0);
  // q(1000 mm) = 2 + 500 + 30 = 532 mm.
  EXPECT_NEAR(q(1.0), 0.532, 1e-12);
}

TEST(ValidateSensorSpecTest, RejectsBadSpecs) {
  const SensorSpec good = *SensorPreset("sr3000");
  auto bad = [&](auto mutate) {
    SensorSpec s = good;
    mutate(s);
    return !ValidateSensorSpec(s).empty();
  };
  EXPECT_TRUE(bad([](SensorSpec& s) { s.epsilon = 0.0; }));
  EXPECT_TRUE(bad([](SensorSpec& s) { s.epsilon = 1.0; }));
  EXPECT_TRUE(bad([](SensorSpec& s) { s.r_max_m = std::nan(""); }));
  EXPECT_TRUE(bad([](SensorSpec& s) { s.r_max_m = INFINITY; }));
  EXPECT_TRUE(bad([](SensorSpec& s) { s.r_min_m = -1.0; }));
  EXPECT_TRUE(bad([](SensorSpec& s) { s.r_max_m = s.r_min_m; }));
  EXPECT_TRUE(bad([](SensorSpec& s) { s.cols = 0; }));
  EXPECT_TRUE(bad([](SensorSpec& s) { s.fov_v_rad = 0.0; }));
  EXPECT_TRUE(bad([](SensorSpec& s) { s.delta = -3.0; }));
  EXPECT_TRUE(bad([](SensorSpec& s) { s.q_sigma.a1 = std::nan(""); }));
  EXPECT_TRUE(bad([](SensorSpec& s) {
    s.model = ForwardModelKind::kClassicBeam;
    s.classic.sigma_hit_m = 0.0;
  }));
  EXPECT_FALSE(bad([](SensorSpec&) {}));
}

}  // namespace
}  // namespace fusion
