// Beam update equations (paper Eqs. 7, 8, 11), Fig. 2 and the stereo bias correction.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <numeric>
#include <random>

#include "fusion/core/beam.h"
#include "fusion/core/beam_grid.h"
#include "fusion/core/fig2.h"

namespace fusion {
namespace {

SensorSpec OneBeam(const std::string& name) {
  SensorSpec s = *SensorPreset(name);
  s.cols = 1;
  s.rows = 1;
  return s;
}

BeamGridOptions Options(double cell_size_m, BeamRepresentation rep) {
  BeamGridOptions o;
  o.cell_size_m = cell_size_m;
  o.representation = rep;
  return o;
}

double Sum(const std::vector<double>& v) { return std::accumulate(v.begin(), v.end(), 0.0); }

const BeamRepresentation kBoth[] = {BeamRepresentation::kDense,
                                    BeamRepresentation::kUnrolledLinkedList};

TEST(Eq7Eq8Test, RoundTripFromRandomCellProbabilities) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  for (int trial = 0; trial < 50; ++trial) {
    std::vector<double> p_m(40);
    for (double& p : p_m) p = 0.02 + 0.9 * u(rng);
    const std::vector<double> p_b = FirstHitFromCells(p_m);  // Eq. 7
    ASSERT_EQ(p_b.size(), 41u);
    EXPECT_NEAR(Sum(p_b), 1.0, 1e-12);                              // Eq. 6
    const std::vector<double> back = CellsFromFirstHit(p_b, -1.0);  // Eq. 8
    for (std::size_t i = 0; i < p_m.size(); ++i) EXPECT_NEAR(back[i], p_m[i], 1e-9) << i;
  }
}

TEST(Eq7Eq8Test, Eq7ByHand) {
  const std::vector<double> p_b = FirstHitFromCells({0.5, 0.2, 1.0, 0.3});
  EXPECT_DOUBLE_EQ(p_b[0], 0.5);
  EXPECT_DOUBLE_EQ(p_b[1], 0.5 * 0.2);
  EXPECT_DOUBLE_EQ(p_b[2], 0.5 * 0.8);
  EXPECT_DOUBLE_EQ(p_b[3], 0.0);
  EXPECT_DOUBLE_EQ(p_b[4], 0.0);
}

// Eq. 8 with a vanishing denominator: the cells after a certain hit carry no information.
TEST(Eq7Eq8Test, NoInformationKeepsTheGivenValue) {
  const std::vector<double> p_b = FirstHitFromCells({0.5, 0.2, 1.0, 0.3, 0.6});
  const std::vector<double> p_m = CellsFromFirstHit(p_b, 0.123);
  EXPECT_NEAR(p_m[0], 0.5, 1e-12);
  EXPECT_NEAR(p_m[1], 0.2, 1e-12);
  EXPECT_NEAR(p_m[2], 1.0, 1e-12);
  EXPECT_EQ(p_m[3], 0.123);  // denominator 0: no information
  EXPECT_EQ(p_m[4], 0.123);
  // Unnormalised weights give the same p(m).
  std::vector<double> scaled = p_b;
  for (double& w : scaled) w *= 1e120;
  EXPECT_NEAR(CellsFromFirstHit(scaled, 0.123)[1], 0.2, 1e-12);
}

TEST(BeamGridTest, InitialStateIsThePrior) {
  for (BeamRepresentation rep : kBoth) {
    const BeamGrid grid(OneBeam("sr3000"), Options(0.005, rep));
    // Default prior: a 5 cm run starts at 0.5.
    EXPECT_NEAR(grid.PriorOccupancy(0.05), 0.5, 1e-12);
    EXPECT_NEAR(grid.prior_cell_occupancy(), 1.0 - std::pow(0.5, 0.1), 1e-15);
    const std::vector<double> p_m = grid.CellProbabilities(0);
    for (double p : p_m) EXPECT_NEAR(p, grid.prior_cell_occupancy(), 1e-12);
    EXPECT_NEAR(Sum(grid.FirstHitProbabilities(0)), 1.0, 1e-12);
    EXPECT_FALSE(grid.Touched(0));
  }
}

// Eq. 11 keeps p(B) a distribution after every update, for both representations and any
// outcome (range, beyond, below r_min).
TEST(BeamGridTest, FirstHitSumsToOneAfterEveryUpdate) {
  for (BeamRepresentation rep : kBoth) {
    BeamGrid grid(OneBeam("sr3000"), Options(0.005, rep));
    std::mt19937 rng(3);
    std::uniform_real_distribution<double> range(0.0, 8.0);
    for (int k = 0; k < 60; ++k) {
      Reading r{k % 7 == 3 ? Reading::Kind::kBeyondRange : Reading::Kind::kRange, range(rng)};
      ASSERT_TRUE(grid.Update(0, r));
      const std::vector<double> p_b = grid.FirstHitProbabilities(0);
      ASSERT_NEAR(Sum(p_b), 1.0, 1e-12) << k;
      for (double p : p_b) ASSERT_GE(p, 0.0);
    }
  }
}

// Eq. 11 by hand on a tiny dense beam: posterior = eta * p(r | B_i) * prior.
TEST(BeamGridTest, Eq11AgainstTheModelDirectly) {
  SensorSpec s = OneBeam("sr3000");
  s.r_max_m = 1.0;
  const BeamContext ctx(s, Options(0.01, BeamRepresentation::kDense));
  for (BeamRepresentation rep : kBoth) {
    BeamGrid grid(s, Options(0.01, rep));
    const std::vector<double> before = grid.FirstHitProbabilities(0);
    grid.Update(0, {Reading::Kind::kRange, 0.803});
    const std::vector<double> after = grid.FirstHitProbabilities(0);
    std::vector<double> expected(before.size());
    for (std::size_t i = 0; i < before.size(); ++i) {
      expected[i] = ctx.model().Probability(i, 80) * before[i];
    }
    const double eta = 1.0 / Sum(expected);
    for (std::size_t i = 0; i < before.size(); ++i) EXPECT_NEAR(after[i], eta * expected[i], 1e-12);
  }
}

TEST(BeamGridTest, MissingReadingsLeaveTheBeamUntouched) {
  for (BeamRepresentation rep : kBoth) {
    BeamGrid grid(OneBeam("sr3000"), Options(0.005, rep));
    grid.Update(0, {Reading::Kind::kRange, 2.0});
    const std::vector<double> before = grid.FirstHitProbabilities(0);
    EXPECT_FALSE(grid.Update(0, {Reading::Kind::kMissing, 2.0}));
    EXPECT_FALSE(grid.Update(0, {Reading::Kind::kRange, std::nan("")}));
    EXPECT_FALSE(grid.Update(0, {Reading::Kind::kRange, -1.0}));
    EXPECT_FALSE(grid.Update(0, {Reading::Kind::kRange, INFINITY}));
    EXPECT_EQ(grid.FirstHitProbabilities(0), before);
    EXPECT_THROW(grid.Update(1, {Reading::Kind::kRange, 2.0}), std::out_of_range);
  }
}

// Eqs. 12-14: a beyond-range reading moves mass to B_{N+1}; the visible cells become free.
TEST(BeamGridTest, BeyondRangeReadingsFreeTheBeam) {
  const SensorSpec s = OneBeam("sr3000");
  const BeamContext ctx(s, Options(0.005, BeamRepresentation::kDense));
  const auto& model = dynamic_cast<const Paper3dModel&>(ctx.model());
  const double likelihood_ratio = 0.99 / model.eps_bin();  // p(beyond|B_N+1) / p(beyond|B_i)
  for (BeamRepresentation rep : kBoth) {
    BeamGrid grid(s, Options(0.005, rep));
    const std::size_t n = grid.cells_per_beam();
    const std::size_t cell = 400;  // visible
    const std::vector<double> before = grid.FirstHitProbabilities(0);
    grid.Update(0, {Reading::Kind::kBeyondRange, 0.0});
    const std::vector<double> p_b = grid.FirstHitProbabilities(0);
    EXPECT_GT(p_b[n], before[n]);
    EXPECT_NEAR((p_b[n] / p_b[cell]) / (before[n] / before[cell]), likelihood_ratio,
                1e-6 * likelihood_ratio);
    // A range above r_limit is the same outcome.
    BeamGrid other(s, Options(0.005, rep));
    other.Update(0, {Reading::Kind::kRange, grid.r_limit_m() + 0.5});
    EXPECT_NEAR(other.FirstHitProbabilities(0)[n], p_b[n], 1e-12 + 1e-9 * p_b[n]);
    // The prior believes in an obstacle somewhere in 7.5 m; a dozen readings overturn it.
    for (int k = 0; k < 12; ++k) grid.Update(0, {Reading::Kind::kBeyondRange, 0.0});
    EXPECT_GT(grid.FirstHitProbabilities(0)[n], 0.99);
    const std::vector<double> p_m = grid.CellProbabilities(0);
    for (std::size_t i = grid.first_visible_cell(); i < n; ++i) {
      ASSERT_LT(p_m[i], 1e-6) << i;
    }
  }
}

// The eps floor on p(beyond | B_i) keeps B_{N+1} from being absorbing: after a spurious
// beyond-range reading, later hits restore the obstacle.
TEST(BeamGridTest, SpuriousBeyondReadingDoesNotEraseAnObstacle) {
  for (BeamRepresentation rep : kBoth) {
    BeamGrid grid(OneBeam("sr3000"), Options(0.005, rep));
    auto peak = [&] {
      const std::vector<double> p_m = grid.CellProbabilities(0);
      return *std::max_element(p_m.begin() + 590, p_m.begin() + 610);  // around 3.0 m
    };
    for (int k = 0; k < 10; ++k) grid.Update(0, {Reading::Kind::kRange, 3.0});
    EXPECT_GT(peak(), 0.9);
    grid.Update(0, {Reading::Kind::kBeyondRange, 0.0});
    for (int k = 0; k < 10; ++k) grid.Update(0, {Reading::Kind::kRange, 3.0});
    EXPECT_GT(peak(), 0.9);
  }
}

// Blind cells (||B_i|| < r_min) have p(r | B_i) = 0: after any reading p(B_i) = 0.
TEST(BeamGridTest, BlindCellsAndReadingsBelowRMin) {
  for (BeamRepresentation rep : kBoth) {
    BeamGrid grid(OneBeam("sr3000"), Options(0.005, rep));
    EXPECT_EQ(grid.first_visible_cell(), 120u);
    ASSERT_TRUE(grid.Update(0, {Reading::Kind::kRange, 0.3}));  // below r_min: follows model
    EXPECT_TRUE(grid.Touched(0));
    const std::vector<double> p_b = grid.FirstHitProbabilities(0);
    for (std::size_t i = 0; i < grid.first_visible_cell(); ++i) EXPECT_EQ(p_b[i], 0.0);
    EXPECT_NEAR(Sum(p_b), 1.0, 1e-12);
  }
}

// Fig. 2: twenty classic-model updates at r = 0.5 concentrate p(B) at B_11.
TEST(Fig2Test, ConcentratesAtCellElevenAndRaisesItsOccupancy) {
  const std::vector<Fig2Row> rows = ReproduceFig2(20);
  ASSERT_EQ(rows.size(), 21u);
  ASSERT_EQ(rows[0].p_b.size(), 22u);
  for (double p : rows[0].p_m) EXPECT_NEAR(p, 0.5, 1e-12);  // uniform start
  for (std::size_t u = 1; u < rows.size(); ++u) {
    EXPECT_GT(rows[u].p_m[10], rows[u - 1].p_m[10]) << "p(m_11) must rise at update " << u;
    EXPECT_GT(rows[u].p_b[10], rows[u - 1].p_b[10]) << "p(B_11) must rise at update " << u;
    EXPECT_NEAR(Sum(rows[u].p_b), 1.0, 1e-12);
  }
  const Fig2Row& last = rows.back();
  const auto argmax = std::max_element(last.p_b.begin(), last.p_b.end()) - last.p_b.begin();
  EXPECT_EQ(argmax, 10);  // B_11
  EXPECT_GT(last.p_b[10], 0.7);
  EXPECT_GT(last.p_m[10], 0.9);
  for (std::size_t i = 0; i < 10; ++i) EXPECT_LT(last.p_m[i], 0.2) << "cell " << i + 1;
  for (std::size_t i = 0; i < 9; ++i) {
    for (std::size_t u = 2; u < rows.size(); ++u) {
      EXPECT_LE(rows[u].p_m[i], rows[u - 1].p_m[i] + 1e-15) << "cell " << i + 1 << " u " << u;
    }
  }
}

// The stereo camera reads a surface at 3.0 m as ~3.37 m; the forward model puts it back.
TEST(BiasCorrectionTest, StereoSurfaceLandsAtThreeMetres) {
  const SensorSpec s = OneBeam("stoc");
  const double truth = 3.0;
  const double mu = s.q_mu(truth);
  const double sigma = s.q_sigma(truth);
  ASSERT_NEAR(mu, 3.37245, 1e-4);
  for (BeamRepresentation rep : kBoth) {
    for (unsigned seed : {1u, 2u, 3u}) {
      BeamGrid grid(s, Options(0.001, rep));
      std::mt19937 rng(seed);
      std::normal_distribution<double> reading(mu, sigma);
      for (int k = 0; k < 30; ++k) grid.Update(0, {Reading::Kind::kRange, reading(rng)});
      const std::vector<double> p_b = grid.FirstHitProbabilities(0);
      const std::size_t best =
          std::max_element(p_b.begin(), p_b.end() - 1) - p_b.begin();  // cells only
      const double range = (best + 0.5) * 0.001;
      EXPECT_NEAR(range, truth, 2.0 * sigma) << "seed " << seed;
      EXPECT_GT(std::abs(range - mu), 0.25) << "must not sit at the biased mean";
    }
  }
}

// IntervalOccupancy: telescoping product of (1 - p(m_i)) over cell ranges.
TEST(IntervalOccupancyTest, MatchesTheProductOfCellProbabilities) {
  for (BeamRepresentation rep : kBoth) {
    BeamGrid grid(OneBeam("sr3000"), Options(0.005, rep));
    for (double r : {2.0, 2.01, 1.99, 4.5}) grid.Update(0, {Reading::Kind::kRange, r});
    const std::vector<double> p_m = grid.CellProbabilities(0);
    const std::vector<double> bounds = {0.0, 0.5, 1.0, 1.95, 2.0, 2.05, 3.0, 7.5};
    std::vector<double> out;
    grid.IntervalOccupancy(0, bounds, &out);
    ASSERT_EQ(out.size(), bounds.size() - 1);
    for (std::size_t j = 0; j + 1 < bounds.size(); ++j) {
      const std::size_t a = static_cast<std::size_t>(std::lround(bounds[j] / 0.005));
      const std::size_t b = static_cast<std::size_t>(std::lround(bounds[j + 1] / 0.005));
      double free = 1.0;
      for (std::size_t i = a; i < b; ++i) free *= 1.0 - p_m[i];
      EXPECT_NEAR(out[j], 1.0 - free, 1e-9) << j;
    }
    // Untouched beam: the prior of each interval.
    BeamGrid fresh(OneBeam("sr3000"), Options(0.005, rep));
    fresh.IntervalOccupancy(0, {1.0, 1.05, 1.2}, &out);
    EXPECT_NEAR(out[0], 0.5, 1e-9);
    EXPECT_NEAR(out[1], fresh.PriorOccupancy(0.15), 1e-9);
    // Degenerate inputs never crash.
    fresh.IntervalOccupancy(0, {std::nan(""), -3.0, 100.0, 2.0}, &out);
    EXPECT_EQ(out.size(), 3u);
    fresh.IntervalOccupancy(0, {1.0}, &out);
    EXPECT_TRUE(out.empty());
  }
}

}  // namespace
}  // namespace fusion
