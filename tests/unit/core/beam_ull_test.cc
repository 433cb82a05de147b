// Unrolled linked list beams (paper Sec. IV-A) against the dense reference.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include "fusion/core/beam.h"
#include "fusion/core/beam_grid.h"

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

// A mixed sequence: readings of a surface drawn from the model, uniform clutter (some beyond
// r_limit, some below r_min), explicit beyond-range points, missing and invalid readings.
std::vector<Reading> RandomReadings(const SensorSpec& s, double r_limit, unsigned seed, int count) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  const double surface = s.r_min_m + (s.r_max_m - s.r_min_m) * u(rng);
  std::normal_distribution<double> hit(s.q_mu(surface), s.q_sigma(surface));
  std::vector<Reading> out;
  for (int k = 0; k < count; ++k) {
    const double pick = u(rng);
    if (pick < 0.08) {
      out.push_back({Reading::Kind::kMissing, 0.0});
    } else if (pick < 0.12) {
      out.push_back({Reading::Kind::kRange, std::nan("")});
    } else if (pick < 0.22) {
      out.push_back({Reading::Kind::kBeyondRange, 0.0});
    } else if (pick < 0.40) {
      out.push_back({Reading::Kind::kRange, 1.1 * r_limit * u(rng)});
    } else {
      out.push_back({Reading::Kind::kRange, hit(rng)});
    }
  }
  return out;
}

void ExpectEquivalent(const SensorSpec& s, double cell_size_m, unsigned seed, int readings) {
  BeamGrid dense(s, Options(cell_size_m, BeamRepresentation::kDense));
  BeamGrid ull(s, Options(cell_size_m, BeamRepresentation::kUnrolledLinkedList));
  for (const Reading& r : RandomReadings(s, dense.r_limit_m(), seed, readings)) {
    EXPECT_EQ(dense.Update(0, r), ull.Update(0, r));
  }
  const std::vector<double> a = dense.CellProbabilities(0);
  const std::vector<double> b = ull.CellProbabilities(0);
  ASSERT_EQ(a.size(), b.size());
  double worst = 0.0;
  for (std::size_t i = 0; i < a.size(); ++i) worst = std::max(worst, std::abs(a[i] - b[i]));
  EXPECT_LE(worst, 1e-3) << s.name << " seed " << seed;
  const std::vector<double> pa = dense.FirstHitProbabilities(0);
  const std::vector<double> pb = ull.FirstHitProbabilities(0);
  for (std::size_t i = 0; i < pa.size(); ++i) ASSERT_NEAR(pa[i], pb[i], 1e-9) << i;
  std::vector<double> bounds, oa, ob;
  for (double x = 0.0; x < s.r_max_m + 0.1; x += 0.137) bounds.push_back(x);
  dense.IntervalOccupancy(0, bounds, &oa);
  ull.IntervalOccupancy(0, bounds, &ob);
  for (std::size_t j = 0; j < oa.size(); ++j) ASSERT_NEAR(oa[j], ob[j], 1e-6) << j;
  // A span's tail masses in one walk: S(c) / S(0) is the dense tail sum, for any stretch.
  {
    std::vector<double> tail(pa.size() + 1, 0.0);
    for (std::size_t i = pa.size(); i-- > 0;) tail[i] = tail[i + 1] + pa[i];
    const auto n = static_cast<std::uint32_t>(dense.cells_per_beam());
    const std::vector<std::pair<std::uint32_t, std::uint32_t>> spans = {
        {0, n}, {n / 3, n / 2}, {n - 5, n}, {n / 2, n / 2}, {0, 7}};
    for (const auto& [first, last] : spans) {
      for (const BeamGrid* grid : {&dense, &ull}) {
        std::vector<double> span;
        double total = 0.0;
        grid->TailMassSpan(0, first, last, &span, &total);
        ASSERT_EQ(span.size(), last - first + 1);
        for (std::uint32_t c = first; c <= last; ++c) {
          ASSERT_NEAR(span[c - first] / total, tail[c], 1e-9)
              << s.name << " seed " << seed << " span " << first << ".." << last << " cell " << c;
        }
      }
    }
  }
  // Where the remaining first-hit mass falls below a fraction of what it was at from_m:
  // both representations against the tail sums of the dense p(B).
  std::vector<double> tail(pa.size() + 1, 0.0);
  for (std::size_t i = pa.size(); i-- > 0;) tail[i] = tail[i + 1] + pa[i];
  const auto tail_drop_m = [&](double fraction, double from_m) {
    const auto from = static_cast<std::size_t>(std::lround(from_m / cell_size_m));
    for (std::size_t c = from + 1; c < pa.size(); ++c) {
      if (tail[c] < fraction * tail[from]) return static_cast<double>(c) * cell_size_m;
    }
    return std::numeric_limits<double>::infinity();
  };
  const auto expect_at = [&](double got, double expected, const BeamGrid* grid,
                             const std::string& what) {
    if (std::isinf(expected)) {
      EXPECT_TRUE(std::isinf(got)) << s.name << " seed " << seed << " " << what << " got " << got
                                   << (grid == &dense ? " dense" : " list");
    } else {
      // The dense beam sums exactly as above; the list's sums may put a crossing that lies
      // right at the threshold one cell off.
      EXPECT_NEAR(got, expected, grid == &dense ? 1e-12 : 1.01 * cell_size_m)
          << s.name << " seed " << seed << " " << what << (grid == &dense ? " dense" : " list");
    }
  };
  for (const double fraction : {1e-2, 0.5, 1e-6}) {
    for (const double from_m : {0.0, s.r_min_m, 0.5 * s.r_max_m}) {
      const std::string what =
          "from " + std::to_string(from_m) + " fraction " + std::to_string(fraction);
      for (const BeamGrid* grid : {&dense, &ull}) {
        expect_at(grid->InformationEndM(0, from_m, fraction), tail_drop_m(fraction, from_m), grid,
                  what);
        // A render's profile of the beam, from where its rays start, finds its information end
        // and median (1/2) the same. (From the middle of a beam the list's profile can differ:
        // the classic model's beams of seeds 2, 3 and 5 from 3.75 m are infinite where the tail
        // sums end. Renders never ask there.)
        if (from_m > s.r_min_m) continue;
        const BeamProfile profile = grid->Profile(0, from_m, fraction, 2.0);
        expect_at(profile.info_end_m, tail_drop_m(fraction, from_m), grid, "profile " + what);
        expect_at(profile.median_m, tail_drop_m(0.5, from_m), grid, "profile median " + what);
      }
    }
  }
}

TEST(UllEquivalenceTest, ThirtySeedsBothPresetsFiveMillimetreCells) {
  for (const std::string name : {"sr3000", "stoc"}) {
    for (unsigned seed = 1; seed <= 30; ++seed) ExpectEquivalent(OneBeam(name), 0.005, seed, 50);
  }
}

TEST(UllEquivalenceTest, FullLengthOneMillimetreCells) {
  ExpectEquivalent(OneBeam("sr3000"), 0.001, 101, 50);
  ExpectEquivalent(OneBeam("stoc"), 0.001, 102, 50);
}

// Long runs at one surface drive the running total through renormalisation.
TEST(UllEquivalenceTest, ManyReadingsRenormalise) {
  const SensorSpec s = OneBeam("sr3000");
  BeamGrid dense(s, Options(0.002, BeamRepresentation::kDense));
  BeamGrid ull(s, Options(0.002, BeamRepresentation::kUnrolledLinkedList));
  std::mt19937 rng(5);
  std::normal_distribution<double> hit(s.q_mu(2.5), s.q_sigma(2.5));
  for (int k = 0; k < 400; ++k) {
    const Reading r{k % 50 == 49 ? Reading::Kind::kBeyondRange : Reading::Kind::kRange, hit(rng)};
    dense.Update(0, r);
    ull.Update(0, r);
  }
  const std::vector<double> a = dense.CellProbabilities(0);
  const std::vector<double> b = ull.CellProbabilities(0);
  for (std::size_t i = 0; i < a.size(); ++i) ASSERT_NEAR(a[i], b[i], 1e-3) << i;
}

TEST(UllEquivalenceTest, ClassicModelToo) {
  SensorSpec s = OneBeam("sr3000");
  s.model = ForwardModelKind::kClassicBeam;
  for (unsigned seed = 1; seed <= 5; ++seed) ExpectEquivalent(s, 0.01, seed, 50);
}

// The running total stays the weights' sum (its error bound is kept, and the total summed again
// before the bound grows): readings that take away nearly all of the mass (the classic model's
// clutter and beyond-range outcomes) would otherwise leave it orders of magnitude off, and the
// tails derived from it with it.
TEST(UllEquivalenceTest, RunningTotalStaysTheWeightsSum) {
  for (const ForwardModelKind model : {ForwardModelKind::kClassicBeam, ForwardModelKind::kPaper3d}) {
    SensorSpec s = OneBeam("sr3000");
    s.model = model;
    const BeamContext ctx(s, Options(0.01, BeamRepresentation::kUnrolledLinkedList));
    UllBeam beam(ctx);
    std::mt19937 rng(3);
    std::uniform_int_distribution<std::size_t> outcome(0, ctx.disc().beyond_outcome());
    std::vector<double> w;
    for (int k = 0; k < 200; ++k) {
      beam.Update(ctx, outcome(rng));
      beam.Weights(ctx, &w);
      double exact = 0.0;
      for (const double v : w) exact += v;
      ASSERT_NEAR(beam.running_total() / exact, 1.0, 1e-9) << "update " << k;
    }
  }
}

TEST(UllStructureTest, SplitsIntoAtMostThreePiecesAndMerges) {
  const SensorSpec s = OneBeam("sr3000");
  const BeamContext ctx(s, Options(0.001, BeamRepresentation::kUnrolledLinkedList));
  UllBeam beam(ctx);
  ASSERT_EQ(beam.composites().size(), 2u);  // blind UEC + visible UEC, split at r_min
  EXPECT_EQ(beam.composites()[1].first, 600u);
  const std::size_t bin = 3000;
  const BeamContext::RoiFactors roi = ctx.Roi(bin);
  ASSERT_GT(roi.end, roi.begin);
  beam.Update(ctx, bin);
  // blind UEC, visible UEC, EC over the ROI, visible UEC.
  ASSERT_EQ(beam.composites().size(), 4u);
  const UllBeam::Composite& ec = beam.composites()[2];
  EXPECT_EQ(ec.exploded, 1u);
  EXPECT_EQ(ec.first, roi.begin);
  EXPECT_EQ(ec.count, roi.end - roi.begin);
  EXPECT_EQ(beam.exploded_cell_count(), roi.end - roi.begin);
  // A reading whose ROI overlaps the EC extends it instead of adding pieces.
  beam.Update(ctx, bin + 10);
  EXPECT_EQ(beam.composites().size(), 4u);
  // A disjoint ROI adds an EC and a UEC; the list alternates.
  beam.Update(ctx, 5000);
  EXPECT_EQ(beam.composites().size(), 6u);
  for (std::size_t k = 1; k < beam.composites().size(); ++k) {
    const auto& prev = beam.composites()[k - 1];
    const auto& cur = beam.composites()[k];
    EXPECT_EQ(prev.first + prev.count, cur.first);
    if (k >= 2) {
      EXPECT_NE(prev.exploded, cur.exploded);
    }
  }
  // Beyond-range readings touch no cell (empty ROI).
  const std::size_t exploded = beam.exploded_cell_count();
  beam.Update(ctx, ctx.disc().beyond_outcome());
  EXPECT_EQ(beam.exploded_cell_count(), exploded);
}

// Eq. 17 by Simpson's rule: exact for a UEC outside every ROI (constant model), close to the
// exact weighted average for a smooth model.
TEST(UllCompositeModelTest, SimpsonMatchesEq17) {
  const SensorSpec s = OneBeam("sr3000");
  const BeamContext ctx(s, Options(0.001, BeamRepresentation::kUnrolledLinkedList));
  UllBeam beam(ctx);
  beam.Update(ctx, 3000);
  const auto& list = beam.composites();
  const std::size_t far_uec = 3;   // visible UEC after the EC
  const std::size_t near_uec = 1;  // visible UEC before the EC
  const std::size_t blind = 0;
  for (std::size_t o : {std::size_t{100}, std::size_t{3000}, ctx.disc().beyond_outcome()}) {
    const double floor = ctx.model().OutsideRoiProbability(o);
    EXPECT_DOUBLE_EQ(beam.CompositeModel(ctx, far_uec, o), floor);
    EXPECT_DOUBLE_EQ(beam.CompositeModel(ctx, near_uec, o), floor);
    EXPECT_DOUBLE_EQ(beam.CompositeModel(ctx, blind, o), 0.0);
    EXPECT_NEAR(beam.CompositeModelExact(ctx, far_uec, o), floor, 1e-15);
  }
  // EC: the exact weighted average.
  ASSERT_EQ(list[2].exploded, 1u);
  EXPECT_DOUBLE_EQ(beam.CompositeModel(ctx, 2, 3000), beam.CompositeModelExact(ctx, 2, 3000));
  // A UEC straddling a smooth model (classic, short-reading term): Simpson ~ Eq. 17.
  SensorSpec c = s;
  c.model = ForwardModelKind::kClassicBeam;
  c.r_min_m = 0.0;
  c.classic.sigma_hit_m = 2.0;
  BeamGridOptions o = Options(0.01, BeamRepresentation::kUnrolledLinkedList);
  o.prior_cell_occupancy = 0.001;
  const BeamContext cctx(c, o);
  const UllBeam fresh(cctx);
  ASSERT_EQ(fresh.composites().size(), 1u);
  for (std::size_t bin : {std::size_t{50}, std::size_t{300}, std::size_t{700}}) {
    const double simpson = fresh.CompositeModel(cctx, 0, bin);
    const double exact = fresh.CompositeModelExact(cctx, 0, bin);
    EXPECT_NEAR(simpson, exact, 0.1 * exact) << bin;
  }
}

TEST(UllMemoryTest, FarSmallerThanDense) {
  SensorSpec s = *SensorPreset("sr3000");
  s.cols = 16;
  s.rows = 16;
  BeamGrid dense(s, Options(0.001, BeamRepresentation::kDense));
  BeamGrid ull(s, Options(0.001, BeamRepresentation::kUnrolledLinkedList));
  const std::size_t ull_fresh = ull.MemoryBytes();
  for (std::size_t b = 0; b < dense.beam_count(); ++b) {
    dense.Update(b, {Reading::Kind::kRange, 3.0});
    ull.Update(b, {Reading::Kind::kRange, 3.0});
  }
  EXPECT_GT(dense.MemoryBytes(), 256u * 7501u * 8u);
  // The shared factor table (~5 MB) dominates a 256-beam grid; per beam the ULL grows by
  // about one ROI of doubles.
  EXPECT_LT(ull.MemoryBytes() * 3, dense.MemoryBytes());
  EXPECT_LT(ull.MemoryBytes() - ull_fresh, 256u * 1024u);
}

}  // namespace
}  // namespace fusion
