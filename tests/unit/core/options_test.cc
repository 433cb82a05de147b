// Core's option structs: their defaults are valid, and IsValid names the field that is not.
#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <limits>
#include <string>
#include <utility>
#include <vector>

#include "fusion/core/beam_types.h"
#include "fusion/core/forward_model.h"
#include "fusion/core/local_grid.h"
#include "fusion/core/world_map.h"

namespace fusion {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kInf = std::numeric_limits<double>::infinity();

TEST(Options, DefaultsAreValidAndComeFromTheConstants) {
  std::string why;
  EXPECT_TRUE(BeamGridOptions{}.IsValid(&why)) << why;
  EXPECT_TRUE(RenderOptions{}.IsValid(&why)) << why;
  EXPECT_TRUE(WorldMapOptions{}.IsValid(&why)) << why;
  EXPECT_TRUE(WorldMapOptions{}.IsValid());  // why is optional
  EXPECT_EQ(BeamGridOptions{}.cell_size_m, BeamGridOptions::kDefaultCellSizeM);
  EXPECT_EQ(WorldMapOptions{}.resolution_m, RenderOptions{}.resolution_m);
  EXPECT_EQ(RenderOptions{}.combine, VoxelCombine::kMaxLogOdds);  // docs/mapping.md: max
  EXPECT_EQ(WorldMapOptions{}.occupancy_threshold, 0.5);
  EXPECT_NEAR(WorldMapOptions{}.pose_tolerance_rad, M_PI / 180.0, 1e-15);
}

// Each case breaks one field of the default options; IsValid must refuse it and its message
// must start with the field's path.
template <typename Options>
void ExpectRefused(
    const std::vector<std::pair<std::function<void(Options*)>, std::string>>& cases) {
  for (const auto& [spoil, field] : cases) {
    Options options;
    spoil(&options);
    std::string why;
    EXPECT_FALSE(options.IsValid(&why)) << field;
    EXPECT_EQ(why.rfind(field + " ", 0), 0u) << field << " gave: " << why;
    EXPECT_FALSE(options.IsValid()) << field;
  }
}

TEST(Options, BeamGridOptionsNameTheBadField) {
  ExpectRefused<BeamGridOptions>({
      {[](BeamGridOptions* o) { o->cell_size_m = 0.0; }, "cell_size_m"},
      {[](BeamGridOptions* o) { o->cell_size_m = 5.0; }, "cell_size_m"},
      {[](BeamGridOptions* o) { o->cell_size_m = kNaN; }, "cell_size_m"},
      {[](BeamGridOptions* o) { o->prior_cell_occupancy = 1.0; }, "prior_cell_occupancy"},
      {[](BeamGridOptions* o) { o->prior_reference_length_m = 0.0; }, "prior_reference_length_m"},
      {[](BeamGridOptions* o) { o->prior_reference_length_m = kInf; }, "prior_reference_length_m"},
  });
  BeamGridOptions explicit_prior;
  explicit_prior.prior_cell_occupancy = 0.01;
  explicit_prior.prior_reference_length_m = kNaN;  // unused with an explicit prior
  EXPECT_TRUE(explicit_prior.IsValid());
}

TEST(Options, RenderOptionsNameTheBadField) {
  ExpectRefused<RenderOptions>({
      {[](RenderOptions* o) { o->resolution_m = 0.0; }, "resolution_m"},
      {[](RenderOptions* o) { o->resolution_m = 11.0; }, "resolution_m"},
      {[](RenderOptions* o) { o->free_ratio = 0.0; }, "free_ratio"},
      {[](RenderOptions* o) { o->tail_mass = 1.0; }, "tail_mass"},
      {[](RenderOptions* o) { o->max_subrays_per_axis = 0; }, "max_subrays_per_axis"},
      {[](RenderOptions* o) { o->max_range_m = -1.0; }, "max_range_m"},
      {[](RenderOptions* o) { o->max_range_m = kInf; }, "max_range_m"},
      {[](RenderOptions* o) { o->min_incidence_deg = 90.0; }, "min_incidence_deg"},
      {[](RenderOptions* o) { o->max_surface_subrays_per_axis = 0; },
       "max_surface_subrays_per_axis"},
      {[](RenderOptions* o) { o->max_abs_log_odds = 0.0; }, "max_abs_log_odds"},
      {[](RenderOptions* o) { o->threads = RenderOptions::kMaxThreads + 1; }, "threads"},
  });
}

TEST(Options, WorldMapOptionsNameTheBadFieldIncludingNestedOnes) {
  ExpectRefused<WorldMapOptions>({
      {[](WorldMapOptions* o) { o->resolution_m = 100.0; }, "resolution_m"},
      {[](WorldMapOptions* o) { o->pose_tolerance_m = -0.1; }, "pose_tolerance_m"},
      {[](WorldMapOptions* o) { o->pose_tolerance_rad = 4.0; }, "pose_tolerance_rad"},
      {[](WorldMapOptions* o) { o->clamping_min_probability = 0.0; }, "clamping_min_probability"},
      {[](WorldMapOptions* o) { o->clamping_max_probability = 0.0001; },
       "clamping_min_probability"},
      {[](WorldMapOptions* o) { o->occupancy_threshold = 1.0; }, "occupancy_threshold"},
      {[](WorldMapOptions* o) { o->beam_prior_length_m = 0.0; }, "beam_prior_length_m"},
      {[](WorldMapOptions* o) { o->beam_grid.cell_size_m = 2.0; }, "beam_grid.cell_size_m"},
      {[](WorldMapOptions* o) { o->render.max_range_m = kNaN; }, "render.max_range_m"},
      {[](WorldMapOptions* o) { o->render.threads = 1000; }, "render.threads"},
  });
  // The map's resolution overrides the render's, and its beam prior the grid's reference
  // length (SensorGridOptions, MapRenderOptions): those nested fields are not checked.
  WorldMapOptions options;
  options.render.resolution_m = 0.0;
  options.beam_grid.prior_reference_length_m = 0.0;
  EXPECT_TRUE(options.IsValid());
}

TEST(Options, CellsPerBeamRoundsAsTheForwardModel) {
  EXPECT_EQ(CellsPerBeam(7.5, 0.002), 3750u);
  EXPECT_EQ(CellsPerBeam(1.0, 1.0 / 21.0), 21u);  // 1 / (1/21) is 21.000000000000004
  EXPECT_EQ(CellsPerBeam(0.0015, 0.001), 2u);
  EXPECT_EQ(CellsPerBeam(1e-6, 0.001), 1u);  // at least one cell
  SensorSpec spec = *SensorPreset("sr3000");
  const auto model = MakeForwardModel(spec, 0.002);
  EXPECT_EQ(model->discretisation().cell_count, CellsPerBeam(spec.r_max_m, 0.002));
}

}  // namespace
}  // namespace fusion
