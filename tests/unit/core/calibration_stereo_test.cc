// The stereo bias case end to end: a STOC calibrated from boards at 1, 2 and 3 m (known board
// plane) maps a board at 3 m where it is, while a naive unbiased model (q_mu(r) = r) puts it
// where the biased readings land (the paper's q_mu(3 m) = 3.372 m).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>
#include <utility>
#include <vector>

#include "fusion/core/calibration.h"
#include "fusion/core/world_map.h"
#include "fusion/sim/experiment.h"
#include "../../support/calibration_boards.h"
#include "fusion/sim/scene.h"
#include "fusion/sim/simulator.h"

namespace fusion {
namespace {

constexpr double kResM = 0.02;
constexpr double kBoardM = 3.0;

// Fills the field of view at every distance here.
sim::Scene BoardAt(double distance_m) { return testing::BoardAt(distance_m, 4.0); }

sim::SensorRun StereoRun(const SensorSpec& spec, int frames, std::uint64_t seed) {
  sim::SensorRun run;
  run.id = "stoc";
  run.spec = spec;
  run.T_world_sensor = sim::ForwardLookingPose(Eigen::Vector3d::Zero());
  run.sim.seed = seed;
  run.sim.flag_beyond_range = false;  // stereo: r_max = inf
  run.frames = frames;
  return run;
}

// Where the map puts the board: in each column of voxels along x (the viewing direction) in
// front of the board's middle, the centre x of the most probably occupied voxel. (The
// occupied band itself is several voxels thick: sigma is 4.3 cm at 3 m.)
std::vector<double> BoardVoxelsX(const octomap::OcTree& tree) {
  std::map<std::pair<int, int>, std::pair<double, double>> best;  // (y, z) -> (p, x)
  for (auto it = tree.begin_leafs(); it != tree.end_leafs(); ++it) {
    if (!tree.isNodeOccupied(*it) || it.getSize() > 1.5 * kResM) continue;
    if (std::abs(it.getY()) > 1.0 || std::abs(it.getZ()) > 0.8) continue;
    const std::pair<int, int> column(static_cast<int>(std::floor(it.getY() / kResM)),
                                     static_cast<int>(std::floor(it.getZ() / kResM)));
    const double p = it->getOccupancy();
    auto [entry, inserted] = best.try_emplace(column, p, it.getX());
    if (!inserted && p > entry->second.first) entry->second = {p, it.getX()};
  }
  std::vector<double> x;
  for (const auto& [column, value] : best) x.push_back(value.second);
  std::sort(x.begin(), x.end());
  return x;
}

double ShareWithin(const std::vector<double>& x, double centre_m, double half_width_m) {
  const auto n = std::count_if(x.begin(), x.end(),
                               [&](double v) { return std::abs(v - centre_m) <= half_width_m; });
  return static_cast<double>(n) / static_cast<double>(std::max<std::size_t>(1, x.size()));
}

TEST(CalibrationStereo, FittedModelMapsTheBoardWhereItIs) {
  const SensorSpec truth = sim::WithTessellation(*SensorPreset("stoc"), 160, 120);
  // Calibration: three boards, three frames each, the board plane known.
  std::vector<RangeSample> samples;
  for (double distance_m : {1.0, 2.0, 3.0}) {
    const std::vector<sim::OrganizedCloud> clouds =
        sim::SimulateRun(BoardAt(distance_m), StereoRun(truth, 3, 100 + distance_m));
    for (const sim::OrganizedCloud& cloud : clouds) {
      (void)AppendPlaneSamples(cloud.xyz.data(), cloud.size(),
                               sim::ForwardLookingPose(Eigen::Vector3d::Zero()),
                               {1.0, 0.0, 0.0, -distance_m}, {}, &samples);
    }
  }
  const Calibration fit = CalibrateForwardModel(samples);
  ASSERT_TRUE(fit.ok()) << fit.error;
  // Where the reading for t = 3 m lands: 3.372 m (the bias this test is about).
  EXPECT_NEAR(truth.q_mu(kBoardM), 3.372, 0.001);
  EXPECT_NEAR(fit.q_mu(kBoardM), truth.q_mu(kBoardM), 0.003);
  EXPECT_NEAR(fit.q_sigma(kBoardM), truth.q_sigma(kBoardM), 0.1 * truth.q_sigma(kBoardM));

  std::printf(
      "calibrated from %zu samples: q_mu(3 m) = %.4f m (true %.4f), q_sigma(3 m) = "
      "%.4f m (true %.4f), eps %.2g, r %.3f..%.3f m\n",
      fit.samples, fit.q_mu(kBoardM), truth.q_mu(kBoardM), fit.q_sigma(kBoardM),
      truth.q_sigma(kBoardM), fit.epsilon, fit.r_min_m, fit.r_max_m);
  SensorSpec fitted = truth;
  fitted.q_mu = fit.q_mu;
  fitted.q_sigma = fit.q_sigma;
  fitted.epsilon = std::max(fit.epsilon, 1e-4);  // noise-free of outliers: keep eps usable
  fitted.r_min_m = fit.r_min_m;
  fitted.r_max_m = fit.r_max_m;
  SensorSpec naive = fitted;
  naive.q_mu = Polynomial2{0.0, 1.0, 0.0};
  naive.r_max_m = truth.r_max_m;

  // The map: 15 frames of the true sensor at a board at 3 m, through each model.
  const std::vector<std::vector<sim::OrganizedCloud>> frames = {
      sim::SimulateRun(BoardAt(kBoardM), StereoRun(truth, 15, 7))};
  WorldMapOptions options;
  options.resolution_m = kResM;
  const auto map_fitted = sim::BuildForwardModelMap({StereoRun(fitted, 15, 7)}, frames, options);
  const auto map_naive = sim::BuildForwardModelMap({StereoRun(naive, 15, 7)}, frames, options);
  // The reference: the same frames through the true model (what mapping itself achieves).
  const auto map_truth = sim::BuildForwardModelMap({StereoRun(truth, 15, 7)}, frames, options);
  const std::vector<double> x_truth = BoardVoxelsX(map_truth->tree());
  const std::vector<double> x_fitted = BoardVoxelsX(map_fitted->tree());
  const std::vector<double> x_naive = BoardVoxelsX(map_naive->tree());
  ASSERT_GT(x_fitted.size(), 1000u);
  ASSERT_GT(x_naive.size(), 1000u);
  const double median_fitted = x_fitted[x_fitted.size() / 2];
  const double median_naive = x_naive[x_naive.size() / 2];
  const double share_truth = ShareWithin(x_truth, kBoardM, kResM);
  const double share_fitted = ShareWithin(x_fitted, kBoardM, kResM);
  std::printf(
      "board at %.3f m, %zu voxel columns; board voxel x (median; share within one "
      "voxel of 3 m, within two): true model %.3f m (%.1f %%, %.1f %%), fitted model "
      "%.3f m (%.1f %%, %.1f %%), naive q_mu(r) = r %.3f m (%.1f %%; %.1f %% within one "
      "voxel of q_mu(3 m) = %.3f m)\n",
      kBoardM, x_fitted.size(), x_truth[x_truth.size() / 2], 100.0 * share_truth,
      100.0 * ShareWithin(x_truth, kBoardM, 2 * kResM), median_fitted, 100.0 * share_fitted,
      100.0 * ShareWithin(x_fitted, kBoardM, 2 * kResM), median_naive,
      100.0 * ShareWithin(x_naive, kBoardM, kResM),
      100.0 * ShareWithin(x_naive, truth.q_mu(kBoardM), kResM), truth.q_mu(kBoardM));
  // Fitted: the board lies within one voxel of the true 3.0 m, as with the true model (whose
  // per-column peaks scatter by about a voxel: 15 readings with sigma = 4.3 cm each).
  EXPECT_NEAR(median_fitted, kBoardM, kResM);
  EXPECT_GT(share_fitted, 0.6);
  EXPECT_GT(share_fitted, share_truth - 0.05);
  EXPECT_GT(ShareWithin(x_fitted, kBoardM, 2 * kResM), 0.95);
  // Naive: the board where the biased readings land (q_mu(3 m) = 3.372 m), none at 3 m.
  EXPECT_NEAR(median_naive, truth.q_mu(kBoardM), 0.05);
  EXPECT_LT(ShareWithin(x_naive, kBoardM, 2 * kResM), 0.01);
}

}  // namespace
}  // namespace fusion
