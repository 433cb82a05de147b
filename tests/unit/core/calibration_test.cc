// Forward-model calibration (core/include/fusion/core/calibration.h): round trips on the
// simulator's SR-3000 and STOC readings, with and without gross outliers, the error cases and
// the plane helpers.
#include "fusion/core/calibration.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

#include "../../support/calibration_boards.h"
#include "fusion/sim/scene.h"
#include "fusion/sim/simulator.h"

namespace fusion {
namespace {

using testing::BoardAt;

PlaneCoefficients BoardPlane(double distance_m) { return {1.0, 0.0, 0.0, -distance_m}; }

struct Simulated {
  std::vector<RangeSample> samples;
  double true_outlier_fraction = 0.0;
};

// Readings of the preset's model drawn by the project's simulator (q_mu(t) + q_sigma(t) N(0, 1)
// per beam) on boards from r_min to beyond 5 m, on a 32 x 24 subsample of the beams; then a
// share eps of the readings replaced by outliers uniform over [r_min, r_max] (the simulator
// draws none). The true ranges come from the board plane through AppendPlaneSamples.
Simulated Simulate(const std::string& preset, double eps, int frames_per_board,
                   std::uint64_t seed) {
  SensorSpec spec = sim::WithTessellation(*SensorPreset(preset), 32, 24);
  const double r_max_m = spec.r_max_m;
  spec.r_max_m = 10.0;  // the simulator cuts readings beyond r_max; the beam is longer here
  sim::SimOptions options;
  options.seed = seed;
  options.flag_beyond_range = false;
  const Eigen::Isometry3d T_world_sensor = sim::ForwardLookingPose(Eigen::Vector3d::Zero());
  Simulated out;
  const std::vector<double> boards = {spec.r_min_m + 0.02, 0.9, 1.3, 1.8, 2.4, 3.0, 3.7, 4.5};
  for (std::size_t k = 0; k < boards.size(); ++k) {
    sim::RangeSimulator simulator(BoardAt(boards[k]), spec, options);
    simulator.Reseed(seed + k);
    for (int f = 0; f < frames_per_board; ++f) {
      const sim::OrganizedCloud cloud = simulator.Capture(T_world_sensor);
      (void)AppendPlaneSamples(cloud.xyz.data(), cloud.size(), T_world_sensor,
                               BoardPlane(boards[k]), {}, &out.samples);
    }
  }
  std::mt19937_64 rng(seed * 7 + 1);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  std::size_t replaced = 0;
  for (RangeSample& s : out.samples) {
    if (unit(rng) >= eps) continue;
    s.reading_m = spec.r_min_m + unit(rng) * (r_max_m - spec.r_min_m);
    ++replaced;
  }
  out.true_outlier_fraction =
      static_cast<double>(replaced) / static_cast<double>(out.samples.size());
  return out;
}

// Fitted against true polynomials on [r_min, 5 m]: the largest |mu error| (m) and |sigma
// relative error|.
struct Errors {
  double mu_m = 0.0;
  double sigma_rel = 0.0;
};

Errors Compare(const Calibration& fit, const SensorSpec& truth) {
  Errors e;
  for (double t = truth.r_min_m; t <= 5.0 + 1e-9; t += 0.05) {
    e.mu_m = std::max(e.mu_m, std::abs(fit.q_mu(t) - truth.q_mu(t)));
    e.sigma_rel = std::max(e.sigma_rel, std::abs(fit.q_sigma(t) / truth.q_sigma(t) - 1.0));
  }
  return e;
}

void ExpectRoundTrip(const std::string& preset, double eps) {
  const SensorSpec truth = *SensorPreset(preset);
  const Simulated data = Simulate(preset, eps, 40, 11);
  const Calibration fit = CalibrateForwardModel(data.samples);
  ASSERT_TRUE(fit.ok()) << fit.error;
  EXPECT_TRUE(fit.converged);
  const Errors e = Compare(fit, truth);
  std::printf(
      "%s eps %.3f: %zu samples, max |mu error| %.2f mm, max sigma error %.1f %%, "
      "eps fitted %.4f (true %.4f), %d iterations\n",
      preset.c_str(), eps, fit.samples, 1000.0 * e.mu_m, 100.0 * e.sigma_rel, fit.epsilon,
      data.true_outlier_fraction, fit.iterations);
  EXPECT_LT(e.mu_m, 0.005);
  EXPECT_LT(e.sigma_rel, 0.10);
  EXPECT_GT(fit.epsilon, data.true_outlier_fraction / 2.0);
  EXPECT_LT(fit.epsilon, data.true_outlier_fraction * 2.0);
  // The fit is a likelihood maximum: at least as likely as the truth on the same samples.
  const double at_truth =
      CalibrationLogLikelihood(data.samples, truth.q_mu, truth.q_sigma, data.true_outlier_fraction,
                               fit.outlier_lo_m, fit.outlier_hi_m);
  EXPECT_GE(fit.log_likelihood, at_truth - 1e-6 * std::abs(at_truth));
  // Where the data holds inliers: the first board (just past r_min) and the far corners.
  EXPECT_NEAR(fit.r_min_m, truth.r_min_m + 0.02, 0.01);
  EXPECT_GT(fit.r_max_m, 5.0);
  // The table's measured columns are what the truth gives over each bin's inliers (the mean
  // bias and the rms sigma: both vary inside a bin), its fitted ones the curves at the centre.
  ASSERT_EQ(fit.bins.size(), 12u);
  for (const CalibrationBin& bin : fit.bins) {
    EXPECT_NEAR(bin.fitted_bias_m, fit.q_mu(bin.centre_m) - bin.centre_m, 1e-12);
    EXPECT_NEAR(bin.fitted_sigma_m, fit.q_sigma(bin.centre_m), 1e-12);
    if (bin.inliers < 1000) continue;
    double bias = 0.0, var = 0.0;
    std::size_t k = 0;
    for (std::size_t i = 0; i < data.samples.size(); ++i) {
      const double t = data.samples[i].true_range_m;
      if (t < bin.begin_m || t >= bin.end_m || fit.inlier_responsibility[i] < 0.5) continue;
      bias += truth.q_mu(t) - t;
      var += truth.q_sigma(t) * truth.q_sigma(t);
      ++k;
    }
    ASSERT_GT(k, 0u);
    const double sigma_rms = std::sqrt(var / k);
    EXPECT_NEAR(bin.measured_bias_m, bias / k, 0.1 * sigma_rms) << bin.centre_m;
    EXPECT_NEAR(bin.measured_sigma_m, sigma_rms, 0.05 * sigma_rms) << bin.centre_m;
    EXPECT_EQ(bin.inliers + bin.outliers, bin.count);
  }
  // Responsibilities: one per sample, the injected outliers mostly below 1/2.
  ASSERT_EQ(fit.inlier_responsibility.size(), data.samples.size());
  EXPECT_EQ(
      fit.inliers +
          [&] {
            std::size_t n = 0;
            for (double w : fit.inlier_responsibility) n += w < 0.5;
            return n;
          }(),
      data.samples.size());
}

TEST(CalibrationRoundTrip, Sr3000) { ExpectRoundTrip("sr3000", 0.01); }
TEST(CalibrationRoundTrip, Stoc) { ExpectRoundTrip("stoc", 0.01); }
TEST(CalibrationRoundTrip, Sr3000WithGrossOutliers) { ExpectRoundTrip("sr3000", 0.06); }
TEST(CalibrationRoundTrip, StocWithGrossOutliers) { ExpectRoundTrip("stoc", 0.06); }
TEST(CalibrationRoundTrip, StocWithTenPercentGrossOutliers) { ExpectRoundTrip("stoc", 0.11); }

TEST(CalibrationRoundTrip, LowerDegreesFitWhatTheyCan) {
  // The SR-3000's q_mu is the identity: degree 1 finds it exactly; degree 0 (a constant
  // reading) is a bad model, and its likelihood says so.
  const Simulated data = Simulate("sr3000", 0.01, 10, 3);
  CalibrationOptions options;
  options.degree = 1;
  const Calibration linear = CalibrateForwardModel(data.samples, options);
  ASSERT_TRUE(linear.ok()) << linear.error;
  EXPECT_EQ(linear.q_mu.a2, 0.0);
  EXPECT_EQ(linear.q_sigma.a2, 0.0);
  EXPECT_NEAR(linear.q_mu.a1, 1.0, 0.002);
  EXPECT_NEAR(linear.q_mu.a0, 0.0, 0.003);
  const Calibration quadratic = CalibrateForwardModel(data.samples);
  ASSERT_TRUE(quadratic.ok()) << quadratic.error;
  EXPECT_GE(quadratic.log_likelihood, linear.log_likelihood);
}

TEST(CalibrationRoundTrip, ConvergedIsAMaximum) {
  // Many more EM iterations than the tolerance stops at gain next to nothing and move nothing.
  const Simulated data = Simulate("stoc", 0.06, 10, 9);
  const Calibration fit = CalibrateForwardModel(data.samples);
  ASSERT_TRUE(fit.ok()) << fit.error;
  CalibrationOptions longer;
  longer.tolerance = 0.0;
  longer.max_iterations = 60;
  const Calibration more = CalibrateForwardModel(data.samples, longer);
  ASSERT_TRUE(more.ok()) << more.error;
  EXPECT_EQ(more.iterations, 60);
  EXPECT_GE(more.log_likelihood, fit.log_likelihood - 1e-6);
  EXPECT_LT((more.log_likelihood - fit.log_likelihood) / fit.samples, 1e-7);
  for (double t : {1.0, 2.0, 3.0, 4.0, 5.0}) {
    EXPECT_NEAR(more.q_mu(t), fit.q_mu(t), 1e-4) << t;
    EXPECT_NEAR(more.q_sigma(t), fit.q_sigma(t), 1e-3 * fit.q_sigma(t)) << t;
  }
  EXPECT_NEAR(more.epsilon, fit.epsilon, 1e-4);
}

TEST(CalibrationErrors, TooFewSamples) {
  std::vector<RangeSample> samples;
  for (int i = 0; i < 50; ++i) samples.push_back({1.0 + 0.05 * i, 1.0 + 0.05 * i});
  const Calibration fit = CalibrateForwardModel(samples);
  EXPECT_FALSE(fit.ok());
  EXPECT_NE(fit.error.find("too few samples on the target: 50"), std::string::npos) << fit.error;
  // The window counts too.
  const Simulated data = Simulate("sr3000", 0.0, 2, 5);
  CalibrationOptions window;
  window.window_min_m = 20.0;
  window.window_max_m = 30.0;
  EXPECT_NE(CalibrateForwardModel(data.samples, window).error.find("too few samples"),
            std::string::npos);
}

TEST(CalibrationErrors, NarrowRangeBandCannotFitDegreeTwo) {
  std::mt19937_64 rng(1);
  std::normal_distribution<double> noise(0.0, 0.01);
  std::uniform_real_distribution<double> band(2.0, 2.2);
  std::vector<RangeSample> samples;
  for (int i = 0; i < 5000; ++i) {
    const double t = band(rng);
    samples.push_back({t, t + noise(rng)});
  }
  const Calibration fit = CalibrateForwardModel(samples);
  ASSERT_FALSE(fit.ok());
  EXPECT_NE(fit.error.find("degenerate range spread"), std::string::npos) << fit.error;
  EXPECT_NE(fit.error.find("--degree 0"), std::string::npos) << fit.error;
  CalibrationOptions constant;
  constant.degree = 0;
  const Calibration fit0 = CalibrateForwardModel(samples, constant);
  ASSERT_TRUE(fit0.ok()) << fit0.error;
  EXPECT_NEAR(fit0.q_sigma.a0, 0.01, 0.001);
}

TEST(CalibrationErrors, TwoBoardsAreTooFewBinsForDegreeTwo) {
  // Spread enough, but only two distances: two populated bins cannot fix a parabola.
  std::mt19937_64 rng(2);
  std::normal_distribution<double> noise(0.0, 0.01);
  std::vector<RangeSample> samples;
  for (int i = 0; i < 4000; ++i) {
    const double t = (i % 2 == 0 ? 1.0 : 3.0) + 0.01 * noise(rng);
    samples.push_back({t, t + noise(rng)});
  }
  const Calibration fit = CalibrateForwardModel(samples);
  ASSERT_FALSE(fit.ok());
  EXPECT_NE(fit.error.find("degenerate range spread: only 2 of 12 range bins"), std::string::npos)
      << fit.error;
  CalibrationOptions linear;
  linear.degree = 1;
  EXPECT_TRUE(CalibrateForwardModel(samples, linear).ok());
}

TEST(CalibrationErrors, MisuseThrows) {
  CalibrationOptions options;
  options.degree = 3;
  EXPECT_THROW((void)CalibrateForwardModel({}, options), std::invalid_argument);
  options.degree = 2;
  options.bins = 0;
  EXPECT_THROW((void)CalibrateForwardModel({}, options), std::invalid_argument);
  EXPECT_THROW((void)NormalizedPlane({0, 0, 0, 1}), std::invalid_argument);
}

TEST(CalibrationPlanes, TrueRangeIsTheRayPlaneIntersection) {
  // Sensor 1 m above a floor z = 0, looking along world +x and pitched down 30 degrees.
  const Eigen::Isometry3d T_world_sensor =
      sim::ForwardLookingPose(Eigen::Vector3d(0, 0, 1.0), 0.0, M_PI / 6.0);
  const float nan = std::numeric_limits<float>::quiet_NaN();
  // Optical axis (hits the floor at 2 m), a ray pointing up (never hits it), a NaN point,
  // a ray nearly parallel to the floor and a point far off the floor (gated).
  const Eigen::Vector3d up_ray = T_world_sensor.linear().transpose() * Eigen::Vector3d(1, 0, 1);
  const Eigen::Vector3d flat = T_world_sensor.linear().transpose() * Eigen::Vector3d(1, 0, -0.05);
  const std::vector<float> xyz = {0.0f,
                                  0.0f,
                                  2.1f,
                                  static_cast<float>(up_ray.x()),
                                  static_cast<float>(up_ray.y()),
                                  static_cast<float>(up_ray.z()),
                                  nan,
                                  nan,
                                  nan,
                                  static_cast<float>(flat.x()),
                                  static_cast<float>(flat.y()),
                                  static_cast<float>(flat.z()),
                                  0.0f,
                                  0.0f,
                                  1.0f};
  std::vector<RangeSample> samples;
  PlaneSampleOptions options;
  options.max_residual_m = 0.2;
  const PlaneSampleStats stats =
      AppendPlaneSamples(xyz.data(), 5, T_world_sensor, {0, 0, 2.0, 0}, options, &samples);
  EXPECT_EQ(stats.points, 5u);
  EXPECT_EQ(stats.missing, 1u);
  EXPECT_EQ(stats.behind, 1u);
  EXPECT_EQ(stats.parallel, 1u);
  EXPECT_EQ(stats.gated, 1u);
  ASSERT_EQ(stats.samples, 1u);
  ASSERT_EQ(samples.size(), 1u);
  EXPECT_NEAR(samples[0].true_range_m, 2.0, 1e-9);
  EXPECT_NEAR(samples[0].reading_m, 2.1, 1e-6);
  EXPECT_THROW(AppendPlaneSamples(nullptr, 1, T_world_sensor, {0, 0, 1, 0}, {}, &samples),
               std::invalid_argument);
}

TEST(CalibrationPlanes, DominantPlaneIsFoundAmongClutter) {
  std::mt19937_64 rng(4);
  std::uniform_real_distribution<double> u(-2.0, 2.0);
  std::normal_distribution<double> noise(0.0, 0.005);
  std::vector<Eigen::Vector3d> points;
  // The plane 0.3 x - 0.2 y + z = 0.5 (60 %), a smaller plane x = 1.5 (25 %), clutter (15 %).
  for (int i = 0; i < 6000; ++i) {
    const double x = u(rng), y = u(rng);
    points.emplace_back(x, y, 0.5 - 0.3 * x + 0.2 * y + noise(rng));
  }
  for (int i = 0; i < 2500; ++i) points.emplace_back(1.5 + noise(rng), u(rng), u(rng));
  for (int i = 0; i < 1500; ++i) points.emplace_back(u(rng), u(rng), u(rng));
  const PlaneFit fit = FitDominantPlane(points);
  ASSERT_TRUE(fit.ok()) << fit.error;
  const PlaneCoefficients truth = NormalizedPlane({0.3, -0.2, 1.0, -0.5});
  EXPECT_LT((fit.plane - truth).norm(), 0.005) << fit.plane.transpose();
  EXPECT_LT(fit.rms_m, 0.008);  // the noise, 5 mm / |(0.3, -0.2, 1)|, and some clutter
  EXPECT_GT(fit.inliers, 5500u);
  // Deterministic: the same answer again.
  EXPECT_EQ(FitDominantPlane(points).plane, fit.plane);

  // Only clutter: no dominant plane; too few points: no target.
  std::vector<Eigen::Vector3d> clutter(points.end() - 1500, points.end());
  const PlaneFit none = FitDominantPlane(clutter);
  EXPECT_FALSE(none.ok());
  EXPECT_NE(none.error.find("no target found"), std::string::npos) << none.error;
  const PlaneFit few = FitDominantPlane({points.begin(), points.begin() + 10});
  EXPECT_NE(few.error.find("only 10 candidate points"), std::string::npos) << few.error;
}

TEST(CalibrationPlanes, NearPointsAreTheCloseOnesInTheWorldFrame) {
  Eigen::Isometry3d T_world_sensor = Eigen::Isometry3d::Identity();
  T_world_sensor.translation() = Eigen::Vector3d(1, 2, 3);
  const std::vector<float> xyz = {0, 0, 1, 0, 0, 5, NAN, NAN, NAN};
  std::vector<Eigen::Vector3d> near;
  AppendNearPointsWorld(xyz.data(), 3, T_world_sensor, 2.0, &near);
  ASSERT_EQ(near.size(), 1u);
  EXPECT_EQ(near[0], Eigen::Vector3d(1, 2, 4));
}

}  // namespace
}  // namespace fusion
