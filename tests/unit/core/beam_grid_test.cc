// BeamGrid::Integrate: point clouds, bad input and statistics.
#include "fusion/core/beam_grid.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>

namespace fusion {
namespace {

BeamGridOptions Options(BeamRepresentation rep) {
  BeamGridOptions o;
  o.cell_size_m = 0.005;
  o.representation = rep;
  return o;
}

SensorSpec Small() {
  SensorSpec s = *SensorPreset("sr3000");
  s.cols = 8;
  s.rows = 6;
  return s;
}

TEST(IntegrateTest, EveryPointIsCountedOnce) {
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const float inf = std::numeric_limits<float>::infinity();
  for (BeamRepresentation rep :
       {BeamRepresentation::kDense, BeamRepresentation::kUnrolledLinkedList}) {
    BeamGrid grid(Small(), Options(rep));
    const std::vector<float> xyz = {
        0.0f, 0.0f, 2.0f,   // updated
        0.1f, 0.1f, 3.0f,   // updated
        0.0f, 0.0f, 9.0f,   // beyond r_limit -> beyond_range
        0.0f, 0.0f, 1.0f,   // marked beyond
        nan,  nan,  nan,    // missing
        0.0f, 0.0f, 0.0f,   // missing
        nan,  0.0f, 1.0f,   // mixed NaN
        inf,  0.0f, 1.0f,   // inf
        0.0f, 0.0f, -1.0f,  // behind the sensor
        5.0f, 0.0f, 1.0f,   // outside the FOV
        0.0f, 0.0f, 0.2f,   // below r_min: a reading, follows the model
    };
    std::vector<std::uint8_t> beyond(11, 0);
    beyond[3] = 1;
    beyond[4] = 1;  // flag on a missing point: still missing
    const IntegrationStats st = grid.Integrate(xyz.data(), 11, beyond);
    EXPECT_EQ(st.updated, 3u);
    EXPECT_EQ(st.beyond_range, 2u);
    EXPECT_EQ(st.missing, 2u);
    EXPECT_EQ(st.rejected_nonfinite, 2u);
    EXPECT_EQ(st.rejected_outside_fov, 2u);
    const std::size_t axis_beam = *grid.tessellation().BeamOf(Eigen::Vector3d(0, 0, 1));
    EXPECT_TRUE(grid.Touched(axis_beam));
    std::size_t touched = 0;
    for (std::size_t b = 0; b < grid.beam_count(); ++b) touched += grid.Touched(b) ? 1 : 0;
    EXPECT_LE(touched, 2u);
  }
}

TEST(IntegrateTest, SeveralPointsInOneBeamAreSeveralSamples) {
  BeamGrid once(Small(), Options(BeamRepresentation::kUnrolledLinkedList));
  BeamGrid twice(Small(), Options(BeamRepresentation::kUnrolledLinkedList));
  const std::vector<float> one = {0.0f, 0.0f, 2.0f};
  const std::vector<float> two = {0.0f, 0.0f, 2.0f, 0.0f, 0.0f, 2.0f};
  once.Integrate(one.data(), 1);
  once.Integrate(one.data(), 1);
  EXPECT_EQ(twice.Integrate(two.data(), 2).updated, 2u);
  const std::size_t b = *once.tessellation().BeamOf(Eigen::Vector3d(0, 0, 1));
  const std::vector<double> a = once.CellProbabilities(b);
  const std::vector<double> c = twice.CellProbabilities(b);
  for (std::size_t i = 0; i < a.size(); ++i) ASSERT_NEAR(a[i], c[i], 1e-12);
  // The range is the Euclidean norm: an off-axis point at the same norm hits the same cell.
  BeamGrid off(Small(), Options(BeamRepresentation::kUnrolledLinkedList));
  const Eigen::Vector3d d = off.tessellation().Direction(b) * 2.0021;  // mid-bin
  const std::vector<float> p = {static_cast<float>(d.x()), static_cast<float>(d.y()),
                                static_cast<float>(d.z())};
  off.Integrate(p.data(), 1);
  const std::vector<double> e = off.CellProbabilities(b);
  const std::vector<double> f = [&] {
    BeamGrid g(Small(), Options(BeamRepresentation::kUnrolledLinkedList));
    g.Update(b, {Reading::Kind::kRange, 2.0021});
    return g.CellProbabilities(b);
  }();
  for (std::size_t i = 0; i < e.size(); ++i) ASSERT_NEAR(e[i], f[i], 1e-9);
}

TEST(IntegrateTest, BadArgumentsThrowBeforeTouchingAnything) {
  BeamGrid grid(Small(), Options(BeamRepresentation::kUnrolledLinkedList));
  const std::vector<float> xyz = {0.0f, 0.0f, 2.0f};
  EXPECT_THROW(grid.Integrate(nullptr, 3), std::invalid_argument);
  EXPECT_THROW(grid.Integrate(xyz.data(), 1, std::vector<std::uint8_t>(2, 0)),
               std::invalid_argument);
  for (std::size_t b = 0; b < grid.beam_count(); ++b) EXPECT_FALSE(grid.Touched(b));
  EXPECT_EQ(grid.Integrate(nullptr, 0).updated, 0u);
  EXPECT_THROW((void)grid.CellProbabilities(grid.beam_count()), std::out_of_range);
}

TEST(BeamGridConstructionTest, RejectsBadOptionsAndSpecs) {
  BeamGridOptions o = Options(BeamRepresentation::kUnrolledLinkedList);
  o.cell_size_m = 0.0;
  EXPECT_THROW(BeamGrid(Small(), o), std::invalid_argument);
  o = Options(BeamRepresentation::kUnrolledLinkedList);
  o.prior_cell_occupancy = 1.0;
  EXPECT_THROW(BeamGrid(Small(), o), std::invalid_argument);
  o.prior_cell_occupancy = std::nan("");
  EXPECT_THROW(BeamGrid(Small(), o), std::invalid_argument);
  SensorSpec s = Small();
  s.epsilon = 0.0;
  EXPECT_THROW(BeamGrid(s, Options(BeamRepresentation::kDense)), std::invalid_argument);
  s = Small();
  s.cols = 0;
  EXPECT_THROW(BeamGrid(s, Options(BeamRepresentation::kDense)), std::invalid_argument);
}

TEST(BeamGridTest, ResetAndMove) {
  BeamGrid grid(Small(), Options(BeamRepresentation::kUnrolledLinkedList));
  grid.Update(3, {Reading::Kind::kRange, 2.0});
  EXPECT_TRUE(grid.Touched(3));
  const std::size_t memory = grid.MemoryBytes();
  grid.Reset();
  EXPECT_FALSE(grid.Touched(3));
  EXPECT_LE(grid.MemoryBytes(), memory);
  BeamGrid moved = std::move(grid);
  EXPECT_EQ(moved.beam_count(), 48u);
  EXPECT_NEAR(moved.CellProbabilities(3)[700], moved.prior_cell_occupancy(), 1e-12);
}

}  // namespace
}  // namespace fusion

namespace fusion {
namespace {

TEST(UpdateEachBeamTest, SameAsOneUpdatePerBeam) {
  BeamGrid a(Small(), Options(BeamRepresentation::kUnrolledLinkedList));
  BeamGrid b(Small(), Options(BeamRepresentation::kUnrolledLinkedList));
  std::vector<Reading> frame(a.beam_count());
  for (std::size_t k = 0; k < frame.size(); ++k) {
    frame[k] = {Reading::Kind::kRange, 1.0 + 0.05 * static_cast<double>(k)};
  }
  frame[3] = {Reading::Kind::kMissing, 0.0};
  frame[4] = {Reading::Kind::kBeyondRange, 0.0};
  frame[5] = {Reading::Kind::kRange, -2.0};
  const IntegrationStats st = a.UpdateEachBeam(frame);
  EXPECT_EQ(st.missing, 2u);
  EXPECT_EQ(st.beyond_range, 1u);
  EXPECT_EQ(st.updated, frame.size() - 3);
  for (std::size_t k = 0; k < frame.size(); ++k) b.Update(k, frame[k]);
  for (std::size_t k = 0; k < frame.size(); ++k) {
    EXPECT_EQ(a.FirstHitProbabilities(k), b.FirstHitProbabilities(k)) << k;
  }
  EXPECT_THROW(a.UpdateEachBeam(std::vector<Reading>(3)), std::invalid_argument);
}

// Beams are made when first updated (beam_store_of.h): an untouched beam costs a slot, and
// reads of it answer what a made beam at its prior does.
TEST(BeamGridTest, UntouchedBeamsCostASlotAndReadAsThePrior) {
  for (BeamRepresentation rep :
       {BeamRepresentation::kDense, BeamRepresentation::kUnrolledLinkedList}) {
    SensorSpec coarse = *SensorPreset("laser_3d");
    coarse.rows = 82;
    const SensorSpec fine = *SensorPreset("laser_3d");  // 368 x 2048
    const BeamGrid small(coarse, Options(rep));
    const BeamGrid large(fine, Options(rep));
    const std::size_t extra_beams = large.beam_count() - small.beam_count();
    EXPECT_LT(large.MemoryBytes() - small.MemoryBytes(), 8 * extra_beams) << static_cast<int>(rep);

    BeamGrid grid(Small(), Options(rep));
    grid.Update(3, {Reading::Kind::kRange, 2.0});
    grid.Reset();  // beam 3 made, back at the prior; beam 4 never made
    EXPECT_FALSE(grid.Touched(3));
    EXPECT_FALSE(grid.Touched(4));
    EXPECT_EQ(grid.FirstHitProbabilities(3), grid.FirstHitProbabilities(4));
    EXPECT_EQ(grid.CellProbabilities(3), grid.CellProbabilities(4));
    const std::vector<double> bounds = {0.5, 1.0, 2.0, 4.0};
    std::vector<double> made, unmade;
    grid.IntervalOccupancy(3, bounds, &made);
    grid.IntervalOccupancy(4, bounds, &unmade);
    EXPECT_EQ(made, unmade);
    EXPECT_EQ(grid.InformationEndM(3, 0.5, 0.01), grid.InformationEndM(4, 0.5, 0.01));
  }
}

// The order in which beams are first updated (and so made) does not change them.
TEST(BeamGridTest, BeamsDoNotDependOnTheOrderTheyWereMade) {
  BeamGrid forward(Small(), Options(BeamRepresentation::kUnrolledLinkedList));
  BeamGrid backward(Small(), Options(BeamRepresentation::kUnrolledLinkedList));
  const std::size_t n = forward.beam_count();
  for (std::size_t b = 0; b < n; ++b) {
    forward.Update(b, {Reading::Kind::kRange, 1.0 + 0.05 * static_cast<double>(b)});
  }
  for (std::size_t b = n; b-- > 0;) {
    backward.Update(b, {Reading::Kind::kRange, 1.0 + 0.05 * static_cast<double>(b)});
  }
  forward.Update(7, {Reading::Kind::kRange, 2.5});
  backward.Update(7, {Reading::Kind::kRange, 2.5});
  for (std::size_t b = 0; b < n; ++b) {
    EXPECT_TRUE(backward.Touched(b));
    EXPECT_EQ(forward.FirstHitProbabilities(b), backward.FirstHitProbabilities(b)) << b;
  }
}

}  // namespace
}  // namespace fusion
