// Change detection in a beam grid (BeamGridOptions::change_run), from the forward model's own
// equations: under the model's noise a static surface almost never restarts a beam; a surface
// that moves by 6 sigma, or disappears, restarts it within the run length; a fresh beam, which
// finds every reading about as likely as its prior does, never restarts.
#include <gtest/gtest.h>

#include <random>
#include <vector>

#include "fusion/core/beam_grid.h"
#include "fusion/core/beam_tessellation.h"
#include "fusion/core/sensor.h"
#include "fusion/sim/simulator.h"

namespace fusion {
namespace {

constexpr std::uint32_t kRun = 3;

class ChangeDetectionTest : public ::testing::Test {
 protected:
  ChangeDetectionTest() : spec_(sim::WithTessellation(*SensorPreset("sr3000"), 4, 4)) {
    options_.change_run = kRun;
  }
  // One reading per beam of a surface at true range r (the model's mean and noise), or
  // beyond range.
  std::vector<Reading> Frame(double r_m) {
    std::vector<Reading> readings(16);
    for (Reading& reading : readings) {
      if (r_m > spec_.r_max_m) {
        reading.kind = Reading::Kind::kBeyondRange;
        continue;
      }
      reading.kind = Reading::Kind::kRange;
      reading.range_m = spec_.q_mu(r_m) + spec_.q_sigma(r_m) * normal_(rng_);
    }
    return readings;
  }
  double Sigma(double r_m) const { return spec_.q_sigma(r_m); }

  SensorSpec spec_;
  BeamGridOptions options_;
  std::mt19937_64 rng_{7};
  std::normal_distribution<double> normal_{0.0, 1.0};
};

// 10 000 readings per beam at 1.3 m, and at 6 m, where a fresh beam's prior holds ~1e-36 of
// its mass and takes several readings to believe the surface: no restart either way, and the
// far beam ends up holding its surface.
TEST_F(ChangeDetectionTest, AStaticSurfaceUnderTheModelsNoiseAlmostNeverTriggers) {
  for (const double r_m : {1.3, 6.0}) {
    BeamGrid grid(spec_, options_);
    std::size_t changes = 0, readings = 0;
    for (int k = 0; k < 10'000; ++k) {
      const IntegrationStats stats = grid.UpdateEachBeam(Frame(r_m));
      changes += stats.changes_detected;
      readings += stats.updated;
    }
    ASSERT_EQ(readings, 160'000u);
    EXPECT_LT(static_cast<double>(changes) / static_cast<double>(readings), 1e-4)
        << changes << " at " << r_m;
    const std::vector<double> p_b = grid.FirstHitProbabilities(5);
    double near = 0.0;
    for (std::uint32_t c = grid.CellOf(spec_.q_mu(r_m) - 3.0 * Sigma(r_m));
         c <= grid.CellOf(spec_.q_mu(r_m) + 3.0 * Sigma(r_m)); ++c) {
      near += p_b[c];
    }
    EXPECT_GT(near, 0.9) << "the beam holds the surface at " << r_m;
  }
}

// A reading of the moved surface is surprising unless its noise brings it near enough the old
// one for the old posterior's tail to explain it (~0.7 % of readings at 6 sigma, on 1 mm cells):
// nearly every beam restarts within the run (97.9 % of 480 here), every one soon after, and
// then holds the new surface only.
TEST_F(ChangeDetectionTest, ASurfaceThatMovesBySixSigmaTriggersWithinTheRun) {
  std::size_t beams = 0, within_run = 0;
  for (const double r_m : {0.8, 1.3, 3.0}) {
    for (int trial = 0; trial < 10; ++trial) {
      BeamGrid grid(spec_, options_);
      for (int k = 0; k < 30; ++k) ASSERT_EQ(grid.UpdateEachBeam(Frame(r_m)).changes_detected, 0u);
      const double moved_m = r_m + 6.0 * Sigma(r_m);
      std::size_t changes = 0;
      for (std::uint32_t k = 0; k < kRun; ++k) {
        changes += grid.UpdateEachBeam(Frame(moved_m)).changes_detected;
      }
      beams += 16;
      within_run += changes;
      for (std::uint32_t k = 0; k < kRun; ++k) {
        changes += grid.UpdateEachBeam(Frame(moved_m)).changes_detected;
      }
      ASSERT_EQ(changes, 16u) << "every beam within twice the run, at " << r_m;
      for (int k = 0; k < 10; ++k) (void)grid.UpdateEachBeam(Frame(moved_m));
      const std::vector<double> p_b = grid.FirstHitProbabilities(trial % 16);
      const auto mass_near = [&](double range_m) {
        double mass = 0.0;
        for (std::uint32_t c = grid.CellOf(range_m - 3.0 * Sigma(r_m));
             c <= grid.CellOf(range_m + 3.0 * Sigma(r_m)); ++c) {
          mass += p_b[c];
        }
        return mass;
      };
      EXPECT_LT(mass_near(spec_.q_mu(r_m)), 1e-3) << "the old surface is forgotten, " << r_m;
      EXPECT_GT(mass_near(spec_.q_mu(moved_m)), 0.5) << "the new one is there, " << r_m;
    }
  }
  EXPECT_GE(static_cast<double>(within_run), 0.95 * static_cast<double>(beams))
      << within_run << " of " << beams << " beams within the run";
}

TEST_F(ChangeDetectionTest, ASurfaceThatDisappearsTriggersAndAFreshBeamNever) {
  BeamGrid grid(spec_, options_);
  for (int k = 0; k < 30; ++k) (void)grid.UpdateEachBeam(Frame(1.3));
  std::size_t changes = 0;
  for (std::uint32_t k = 0; k < kRun; ++k) {
    changes += grid.UpdateEachBeam(Frame(spec_.r_max_m + 1.0)).changes_detected;
  }
  EXPECT_EQ(changes, 16u) << "no return where the surface was";

  std::uniform_real_distribution<double> anywhere(spec_.r_min_m + 0.1, spec_.r_max_m - 0.1);
  for (int trial = 0; trial < 50; ++trial) {
    BeamGrid fresh(spec_, options_);
    for (std::uint32_t k = 0; k < kRun; ++k) {
      EXPECT_EQ(fresh.UpdateEachBeam(Frame(anywhere(rng_))).changes_detected, 0u)
          << "a fresh beam has nothing to contradict";
    }
  }
}

// The dense beams (every cell, the oracle) and the unrolled linked lists decide alike.
TEST_F(ChangeDetectionTest, DenseAndUnrolledBeamsDecideAlike) {
  BeamGridOptions dense = options_;
  dense.representation = BeamRepresentation::kDense;
  BeamGrid ull_grid(spec_, options_), dense_grid(spec_, dense);
  std::size_t changes = 0;
  for (int k = 0; k < 60; ++k) {
    const double r_m = k < 20 ? 1.3 : k < 40 ? 1.5 : spec_.r_max_m + 1.0;
    const std::vector<Reading> frame = Frame(r_m);
    const std::size_t ull = ull_grid.UpdateEachBeam(frame).changes_detected;
    ASSERT_EQ(dense_grid.UpdateEachBeam(frame).changes_detected, ull) << "frame " << k;
    changes += ull;
  }
  EXPECT_GE(changes, 32u) << "both changes seen";
}

// A cloud is one observation of a beam, however many of its readings fall in it (a depth image
// mapped onto a coarser tessellation gives several per beam): a beam whose footprint holds two
// depths in every cloud never restarts; a beam whose whole footprint moves restarts after
// change_run clouds, holding a reading of each earlier cloud of the run and all of the last.
TEST_F(ChangeDetectionTest, ACloudIsOneObservationOfABeam) {
  const std::size_t beam = 5;
  const Eigen::Vector3d direction = BeamTessellation(spec_).Direction(beam);
  // Eight readings of the beam: the first `near` at 1.3 m, the rest at 1.6 m.
  const auto cloud = [&](int near) {
    std::vector<float> xyz;
    for (int k = 0; k < 8; ++k) {
      const double r_m = k < near ? 1.3 : 1.6;
      const double range_m = spec_.q_mu(r_m) + spec_.q_sigma(r_m) * normal_(rng_);
      for (int a = 0; a < 3; ++a) xyz.push_back(static_cast<float>(direction[a] * range_m));
    }
    return xyz;
  };
  BeamGrid edge(spec_, options_);
  for (int c = 0; c < 30; ++c) {
    const std::vector<float> xyz = cloud(3 + c % 3);  // an edge across the footprint, every cloud
    EXPECT_EQ(edge.Integrate(xyz.data(), 8).changes_detected, 0u) << "cloud " << c;
  }
  BeamGrid moving(spec_, options_);
  BeamGridOptions plain = options_;
  plain.change_run = 0;
  BeamGrid expected(spec_, plain);
  std::size_t changes = 0;
  for (int c = 0; c < 3 + static_cast<int>(kRun); ++c) {
    const std::vector<float> xyz = cloud(c < 3 ? 8 : 0);  // the surface moves by 30 cm
    changes += moving.Integrate(xyz.data(), 8).changes_detected;
    if (c >= 3 && c + 1 < 3 + static_cast<int>(kRun)) {
      (void)expected.Integrate(xyz.data(), 1);  // the run's first surprising reading
    } else if (c + 1 == 3 + static_cast<int>(kRun)) {
      (void)expected.Integrate(xyz.data(), 8);  // and the last cloud whole
    }
  }
  EXPECT_EQ(changes, 1u) << "one restart, after the run";
  const std::vector<double> a = moving.FirstHitProbabilities(beam);
  const std::vector<double> b = expected.FirstHitProbabilities(beam);
  ASSERT_EQ(a.size(), b.size());
  for (std::size_t i = 0; i < a.size(); ++i) ASSERT_NEAR(a[i], b[i], 1e-9) << "cell " << i;
}

// A grid reset for a new period (SensorPeriods recycles them) believes nothing any more: the
// new period's readings, wherever they lie, contradict no earlier one.
TEST_F(ChangeDetectionTest, AResetGridHasNothingToContradict) {
  BeamGrid grid(spec_, options_);
  for (int k = 0; k < 30; ++k) (void)grid.UpdateEachBeam(Frame(1.3));
  grid.Reset();
  for (std::uint32_t k = 0; k < 2 * kRun; ++k) {
    EXPECT_EQ(grid.UpdateEachBeam(Frame(2.5)).changes_detected, 0u) << "frame " << k;
  }
}

TEST_F(ChangeDetectionTest, OnByDefaultOffWithARunOfZeroAndOptionsChecked) {
  EXPECT_EQ(BeamGridOptions{}.change_run, kRun);
  BeamGridOptions off;
  off.change_run = 0;
  BeamGrid grid(spec_, off);
  for (int k = 0; k < 30; ++k) (void)grid.UpdateEachBeam(Frame(1.3));
  for (int k = 0; k < 10; ++k) EXPECT_EQ(grid.UpdateEachBeam(Frame(2.0)).changes_detected, 0u);
  BeamGridOptions bad;
  bad.change_run = 101;
  EXPECT_FALSE(bad.IsValid());
  bad.change_run = 3;
  bad.change_min_mass = 0.0;
  std::string why;
  EXPECT_FALSE(bad.IsValid(&why));
  EXPECT_EQ(why.rfind("change_min_mass", 0), 0u) << why;
}

}  // namespace
}  // namespace fusion
