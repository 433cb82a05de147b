// The sensor's noise apart from the reference's error (AppendLocalPlaneSamples, WithLocalNoise;
// core/include/fusion/core/calibration.h): the simulator's SR-3000 on boards, calibrated
// against a reference plane tilted by a few degrees, as poor poses tilt a floor.
#include <gtest/gtest.h>

#include <cmath>
#include <stdexcept>
#include <vector>

#include "fusion/core/calibration.h"
#include "../../support/calibration_boards.h"
#include "fusion/sim/scene.h"
#include "fusion/sim/simulator.h"

namespace fusion {
namespace {

constexpr double kDegree = 3.14159265358979323846 / 180.0;

using testing::BoardAt;

// The board x = distance_m turned by tilt about the vertical through (distance_m, 0, 0).
PlaneCoefficients ReferenceOf(double distance_m, double tilt_rad) {
  const Eigen::Vector3d n(std::cos(tilt_rad), std::sin(tilt_rad), 0.0);
  return {n.x(), n.y(), n.z(), -n.x() * distance_m};
}

struct Drawn {
  std::vector<RangeSample> reference, local;
  LocalSampleStats local_stats;
};

// The SR-3000's readings (its Table II model, every 2nd beam) of boards from 0.9 to 4.5 m,
// against references tilted by tilt_rad.
Drawn Draw(double tilt_rad) {
  const SensorSpec spec = sim::WithTessellation(*SensorPreset("sr3000"), 88, 72);
  sim::SimOptions options;
  options.seed = 5;
  options.flag_beyond_range = false;
  const Eigen::Isometry3d T_world_sensor = sim::ForwardLookingPose(Eigen::Vector3d::Zero());
  Drawn out;
  const std::vector<double> boards = {0.9, 1.3, 1.8, 2.4, 3.0, 3.7, 4.5};
  for (std::size_t k = 0; k < boards.size(); ++k) {
    sim::RangeSimulator simulator(BoardAt(boards[k]), spec, options);
    simulator.Reseed(100 + k);
    const PlaneCoefficients reference = ReferenceOf(boards[k], tilt_rad);
    for (int frame = 0; frame < 4; ++frame) {
      const sim::OrganizedCloud cloud = simulator.Capture(T_world_sensor);
      (void)AppendPlaneSamples(cloud.xyz.data(), cloud.size(), T_world_sensor, reference, {},
                               &out.reference);
      const LocalSampleStats s = AppendLocalPlaneSamples(
          cloud.xyz.data(), cloud.size(), T_world_sensor, reference, {}, {}, &out.local);
      out.local_stats.cells += s.cells;
      out.local_stats.sparse += s.sparse;
      out.local_stats.plane.samples += s.plane.samples;
    }
  }
  return out;
}

double MaxSigmaError(const Calibration& fit, const SensorSpec& truth) {
  double worst = 0.0;
  for (double t = 0.9; t <= 4.5 + 1e-9; t += 0.05) {
    worst = std::max(worst, std::abs(fit.q_sigma(t) / truth.q_sigma(t) - 1.0));
  }
  return worst;
}

TEST(CalibrationLocalNoise, LocalPlanesSeeTheSensorsSigmaThroughATiltedReference) {
  const SensorSpec truth = *SensorPreset("sr3000");
  const Drawn drawn = Draw(3.0 * kDegree);
  EXPECT_GT(drawn.local_stats.cells, 100u);
  EXPECT_GT(drawn.local.size(), drawn.reference.size() / 2);  // far boards: sparse cells
  const Calibration reference = CalibrateForwardModel(drawn.reference);
  const Calibration local = CalibrateForwardModel(drawn.local);
  ASSERT_TRUE(reference.ok()) << reference.error;
  ASSERT_TRUE(local.ok()) << local.error;
  const double reference_error = MaxSigmaError(reference, truth);
  const double local_error = MaxSigmaError(local, truth);
  std::printf("sigma error against the tilted reference %.1f %%, against local planes %.1f %%\n",
              100.0 * reference_error, 100.0 * local_error);
  EXPECT_GT(reference_error, 0.3);  // the tilt's range error counts as noise
  EXPECT_LT(local_error, 0.10);
  // Local planes move with the bias: the local residuals are centred.
  for (double t = 1.0; t <= 4.5; t += 0.5) EXPECT_NEAR(local.q_mu(t), t, 0.002) << t;

  const Calibration merged = WithLocalNoise(reference, local);
  EXPECT_EQ(merged.q_mu.a1, reference.q_mu.a1);
  EXPECT_EQ(merged.q_sigma.a2, local.q_sigma.a2);
  EXPECT_EQ(merged.epsilon, local.epsilon);
  EXPECT_EQ(merged.r_max_m, reference.r_max_m);
  ASSERT_EQ(merged.bins.size(), reference.bins.size());
  for (const CalibrationBin& bin : merged.bins) {
    EXPECT_NEAR(bin.fitted_sigma_m, local.q_sigma(bin.centre_m), 1e-12);
    EXPECT_EQ(bin.fitted_bias_m, reference.bins[&bin - merged.bins.data()].fitted_bias_m);
  }
}

TEST(CalibrationLocalNoise, UntiltedTheLocalSigmaMatchesTheTruthToo) {
  const Drawn drawn = Draw(0.0);
  const Calibration local = CalibrateForwardModel(drawn.local);
  ASSERT_TRUE(local.ok()) << local.error;
  EXPECT_LT(MaxSigmaError(local, *SensorPreset("sr3000")), 0.10);
}

TEST(CalibrationLocalNoise, SparseCellsGiveNoSamples) {
  // Three points on a board: no cell holds enough for a plane.
  const std::vector<float> xyz = {2.0F, 0.0F, 0.0F, 2.0F, 0.01F, 0.0F, 2.0F, 0.0F, 0.01F};
  std::vector<RangeSample> samples;
  const LocalSampleStats s = AppendLocalPlaneSamples(xyz.data(), 3, Eigen::Isometry3d::Identity(),
                                                     {1.0, 0.0, 0.0, -2.0}, {}, {}, &samples);
  EXPECT_EQ(s.plane.points, 3u);
  EXPECT_EQ(s.sparse, 3u);
  EXPECT_TRUE(samples.empty());
  EXPECT_EQ(s.cells, 0u);
}

TEST(CalibrationLocalNoise, MisuseThrows) {
  std::vector<RangeSample> samples;
  const float xyz[3] = {1.0F, 0.0F, 0.0F};
  LocalPlaneOptions bad;
  bad.patch_m = 0.0;
  EXPECT_THROW((void)AppendLocalPlaneSamples(xyz, 1, Eigen::Isometry3d::Identity(),
                                             {1.0, 0.0, 0.0, -1.0}, {}, bad, &samples),
               std::invalid_argument);
  EXPECT_THROW((void)AppendLocalPlaneSamples(nullptr, 1, Eigen::Isometry3d::Identity(),
                                             {1.0, 0.0, 0.0, -1.0}, {}, {}, &samples),
               std::invalid_argument);
  Calibration failed;
  failed.error = "too few samples";
  EXPECT_THROW((void)WithLocalNoise(failed, Calibration{}), std::invalid_argument);
}

}  // namespace
}  // namespace fusion
