// Forward models p(r | B_i) in the documented discrete form (docs/forward-model.md).
#include "fusion/core/forward_model.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>

namespace fusion {
namespace {

SensorSpec Preset(const std::string& name) { return *SensorPreset(name); }

double RowSum(const ForwardModel& m, std::size_t cell) {
  double s = 0.0;
  for (std::size_t o = 0; o < m.discretisation().outcome_count(); ++o) s += m.Probability(cell, o);
  return s;
}

TEST(DiscretisationTest, CellsBinsAndOutcomes) {
  const Paper3dModel m(Preset("sr3000"), 0.001);
  const BeamDiscretisation& d = m.discretisation();
  EXPECT_EQ(d.cell_count, 7500u);
  EXPECT_EQ(d.first_visible_cell, 600u);  // centre 0.6005 m >= r_min = 0.6 m
  EXPECT_DOUBLE_EQ(d.CellRange(0), 0.0005);
  // r_limit = q_mu(||B_N||) + 3 q_sigma(||B_N||).
  const SensorSpec s = Preset("sr3000");
  EXPECT_NEAR(d.r_limit_m, s.q_mu(7.4995) + 3.0 * s.q_sigma(7.4995), 1e-12);
  EXPECT_EQ(d.bin_count, static_cast<std::size_t>(std::ceil(d.r_limit_m / 0.001)));
  EXPECT_EQ(d.OutcomeOf({Reading::Kind::kRange, 3.0004}), 3000u);
  EXPECT_EQ(d.OutcomeOf({Reading::Kind::kRange, 0.0}), 0u);
  EXPECT_EQ(d.OutcomeOf({Reading::Kind::kRange, d.r_limit_m}), d.bin_count - 1);
  EXPECT_EQ(d.OutcomeOf({Reading::Kind::kRange, d.r_limit_m + 1e-6}), d.beyond_outcome());
  EXPECT_EQ(d.OutcomeOf({Reading::Kind::kBeyondRange, 0.0}), d.beyond_outcome());
  EXPECT_FALSE(d.OutcomeOf({Reading::Kind::kMissing, 1.0}).has_value());
  EXPECT_FALSE(d.OutcomeOf({Reading::Kind::kRange, -0.1}).has_value());
  EXPECT_FALSE(d.OutcomeOf({Reading::Kind::kRange, std::nan("")}).has_value());
  EXPECT_FALSE(
      d.OutcomeOf({Reading::Kind::kRange, std::numeric_limits<double>::infinity()}).has_value());
}

// Algorithm III.1, branch by branch.
TEST(Paper3dModelTest, BlindCellIsZeroForEveryOutcome) {
  const Paper3dModel m(Preset("sr3000"), 0.001);
  const auto& d = m.discretisation();
  for (std::size_t cell : {std::size_t{0}, std::size_t{300}, d.first_visible_cell - 1}) {
    for (std::size_t o :
         {std::size_t{0}, std::size_t{500}, std::size_t{3000}, d.beyond_outcome()}) {
      EXPECT_EQ(m.Probability(cell, o), 0.0) << cell << " " << o;
    }
  }
  EXPECT_GT(m.Probability(d.first_visible_cell, d.first_visible_cell), 0.0);
}

TEST(Paper3dModelTest, InRoiIsScaledNormalMass) {
  const SensorSpec s = Preset("stoc");
  const Paper3dModel m(s, 0.001);
  const std::size_t cell = 2999;  // ||B|| = 2.9995 m
  const double mu = s.q_mu(2.9995);
  const double sigma = s.q_sigma(2.9995);
  EXPECT_NEAR(m.mu(cell), mu, 1e-12);
  EXPECT_NEAR(m.sigma(cell), sigma, 1e-12);
  // (1 - eps) * bin mass of N(mu, sigma^2) = (1 - eps) N(r_k) delta for delta << sigma.
  for (double r : {mu, mu + 2.0 * sigma, mu - 2.9 * sigma}) {
    const std::size_t bin = static_cast<std::size_t>(std::floor(r / 0.001));
    const double a = bin * 0.001;
    const double b = a + 0.001;
    const double mass = 0.5 * (std::erf((b - mu) / (sigma * std::sqrt(2.0))) -
                               std::erf((a - mu) / (sigma * std::sqrt(2.0))));
    ASSERT_TRUE(m.InRoi(cell, bin));
    EXPECT_NEAR(m.Probability(cell, bin), 0.99 * mass, 1e-14);
    const double midpoint = 0.99 * NormalDensity(a + 0.0005, mu, sigma) * 0.001;
    EXPECT_NEAR(m.Probability(cell, bin), midpoint, 1e-3 * midpoint);
  }
  // Bin straddling mu + 3 sigma: only the part inside the ROI counts.
  const double edge = mu + 3.0 * sigma;
  const std::size_t bin = static_cast<std::size_t>(std::floor(edge / 0.001));
  ASSERT_TRUE(m.InRoi(cell, bin));
  EXPECT_FALSE(m.InRoi(cell, bin + 1));
  const double inside = 0.5 * (std::erf(3.0 / std::sqrt(2.0)) -
                               std::erf((bin * 0.001 - mu) / (sigma * std::sqrt(2.0))));
  EXPECT_NEAR(m.Probability(cell, bin), 0.99 * inside, 1e-14);
}

TEST(Paper3dModelTest, OutOfRoiAndBeyondAreTheEpsFloor) {
  const Paper3dModel m(Preset("sr3000"), 0.001);
  const auto& d = m.discretisation();
  const double eps_bin = 0.01 / static_cast<double>(d.bin_count + 1);
  EXPECT_DOUBLE_EQ(m.eps_bin(), eps_bin);
  const std::size_t cell = 2999;
  const double sigma = m.sigma(cell);
  const std::size_t far_bin = static_cast<std::size_t>((m.mu(cell) + 3.5 * sigma) / 0.001);
  EXPECT_FALSE(m.InRoi(cell, far_bin));
  EXPECT_DOUBLE_EQ(m.Probability(cell, far_bin), eps_bin);
  EXPECT_DOUBLE_EQ(m.Probability(cell, 100), eps_bin);
  EXPECT_DOUBLE_EQ(m.Probability(cell, d.beyond_outcome()), eps_bin);  // Eq. 12 with a floor
  EXPECT_DOUBLE_EQ(m.OutsideRoiProbability(7), eps_bin);
}

TEST(Paper3dModelTest, AllFreeBeyondVersusNot) {
  const Paper3dModel m(Preset("sr3000"), 0.001);
  const auto& d = m.discretisation();
  const std::size_t all_free = d.cell_count;
  EXPECT_DOUBLE_EQ(m.Probability(all_free, d.beyond_outcome()), 0.99);  // Eq. 14
  EXPECT_DOUBLE_EQ(m.Probability(all_free, 1234), 0.01 / d.bin_count);  // Eq. 13 per bin
  double over_d = 0.0;
  for (std::size_t k = 0; k < d.bin_count; ++k) over_d += m.Probability(all_free, k);
  EXPECT_NEAR(over_d, 0.01, 1e-12);  // Eq. 13
  EXPECT_NEAR(RowSum(m, all_free), 1.0, 1e-12);
}

TEST(Paper3dModelTest, EveryCellSumsToAtMostOneAndAllFreeToOne) {
  for (const std::string name : {"sr3000", "stoc"}) {
    for (double cell_size : {0.001, 0.005, 0.02}) {
      const Paper3dModel m(Preset(name), cell_size);
      const auto& d = m.discretisation();
      const std::size_t step = std::max<std::size_t>(1, d.cell_count / 200);
      for (std::size_t i = 0; i < d.cell_count; i += step) {
        const double s = RowSum(m, i);
        EXPECT_LE(s, 1.0 + 1e-9) << name << " " << cell_size << " cell " << i;
        if (i >= d.first_visible_cell) {
          EXPECT_GT(s, 0.98) << name << " cell " << i;
        }
      }
      EXPECT_NEAR(RowSum(m, d.cell_count), 1.0, 1e-12);
    }
  }
}

// The sparse structure the ULL relies on: outside Roi(o) every visible cell sees the floor.
TEST(Paper3dModelTest, RoiCoversEveryNonFloorCell) {
  for (const std::string name : {"sr3000", "stoc"}) {
    const Paper3dModel m(Preset(name), 0.005);
    const auto& d = m.discretisation();
    for (std::size_t o = 0; o < d.outcome_count(); o += 7) {
      const CellSpan roi = m.Roi(o);
      for (std::size_t i = d.first_visible_cell; i < d.cell_count; ++i) {
        if (i >= roi.begin && i < roi.end) continue;
        ASSERT_EQ(m.Probability(i, o), m.OutsideRoiProbability(o)) << name << " " << i << " " << o;
      }
    }
    EXPECT_TRUE(m.Roi(d.beyond_outcome()).empty());
  }
}

// The ROI part of every visible cell carries (1 - eps) erf(Delta / sqrt 2) at any cell size,
// also when sigma is far below the cell size.
TEST(Paper3dModelTest, RoiMassIsExactAtAnyCellSize) {
  for (double cell_size : {0.001, 0.005, 0.02, 0.1}) {
    const Paper3dModel m(Preset("sr3000"), cell_size);
    const auto& d = m.discretisation();
    for (std::size_t cell = d.first_visible_cell; cell < d.cell_count;
         cell += std::max<std::size_t>(1, d.cell_count / 50)) {
      double in_roi = 0.0;
      for (std::size_t k = 0; k < d.bin_count; ++k) {
        if (m.InRoi(cell, k)) in_roi += m.Probability(cell, k);
      }
      EXPECT_NEAR(in_roi, 0.99 * std::erf(3.0 / std::sqrt(2.0)), 1e-9) << cell_size << " " << cell;
    }
  }
}

TEST(ClassicBeamModelTest, EveryCellSumsToOne) {
  SensorSpec s = Preset("sr3000");
  s.model = ForwardModelKind::kClassicBeam;
  s.r_min_m = 0.0;
  s.r_max_m = 2.0;
  const ClassicBeamModel m(s, 0.01);
  const auto& d = m.discretisation();
  EXPECT_EQ(d.bin_count, 200u);
  EXPECT_DOUBLE_EQ(d.r_limit_m, 2.0);
  for (std::size_t i = 0; i <= d.cell_count; ++i) EXPECT_NEAR(RowSum(m, i), 1.0, 1e-12) << i;
  // max reading: z_max for a cell, z_max + z_hit for B_{N+1}.
  EXPECT_NEAR(m.Probability(50, d.beyond_outcome()), 0.1, 1e-12);
  EXPECT_NEAR(m.Probability(d.cell_count, d.beyond_outcome()), 0.8, 1e-12);
  // short readings only in front of the cell: a reading behind cell 50 has no short term.
  const double in_front = m.Probability(100, 50);
  const double behind = m.Probability(20, 50);
  EXPECT_GT(in_front, behind);
  // The hit peak is at the cell's own bin.
  EXPECT_GT(m.Probability(100, 100), m.Probability(100, 104));
  EXPECT_GT(m.Probability(100, 100), m.Probability(100, 96));
  const CellSpan roi = m.Roi(3);
  EXPECT_EQ(roi.begin, 0u);
  EXPECT_EQ(roi.end, d.cell_count);
}

TEST(ForwardModelFactoryTest, BuildsByKindAndRejectsBadInput) {
  SensorSpec s = Preset("stoc");
  EXPECT_NE(dynamic_cast<Paper3dModel*>(MakeForwardModel(s, 0.01).get()), nullptr);
  s.model = ForwardModelKind::kClassicBeam;
  EXPECT_NE(dynamic_cast<ClassicBeamModel*>(MakeForwardModel(s, 0.01).get()), nullptr);
  EXPECT_THROW((void)MakeForwardModel(s, 0.0), std::invalid_argument);
  EXPECT_THROW((void)MakeForwardModel(s, std::nan("")), std::invalid_argument);
  s.epsilon = 0.0;
  EXPECT_THROW((void)MakeForwardModel(s, 0.01), std::invalid_argument);
}

TEST(NormalDensityTest, Eq15) {
  EXPECT_NEAR(NormalDensity(0.0, 0.0, 1.0), 0.3989422804014327, 1e-15);
  EXPECT_NEAR(NormalDensity(1.0, 0.0, 2.0), std::exp(-0.125) / (2.0 * std::sqrt(2 * M_PI)), 1e-15);
}

}  // namespace
}  // namespace fusion
