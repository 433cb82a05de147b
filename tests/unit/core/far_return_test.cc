// A single return far out (a laser's at 20 m) marks its surface and clears its beam when the
// beam prior does not already expect a surface every metre (5 m does; the map's default 1 m
// does not): map.beam_prior_length_m, or the sensor's own (the laser_3d preset's 5 m);
// BENCHMARKS.md, "The laser scan's beam grid".
#include <gtest/gtest.h>

#include <cmath>
#include <optional>
#include <string>
#include <vector>

#include "fusion/core/world_map.h"

namespace fusion {
namespace {

// The map's occupancy at each of `at_m` on the optical axis after one reading at range_m.
// sensor_prior_m: the laser's own beam prior (0: the map's).
std::vector<std::optional<double>> OccupancyAlongTheAxis(double beam_prior_length_m,
                                                         double range_m,
                                                         const std::vector<double>& at_m,
                                                         double sensor_prior_m = 0.0) {
  WorldMapOptions options;
  options.resolution_m = 0.05;
  options.render.resolution_m = 0.05;
  options.beam_prior_length_m = beam_prior_length_m;
  WorldMap map(options);
  SensorSpec laser = *SensorPreset("laser_3d");
  laser.beam_prior_length_m = sensor_prior_m;
  EXPECT_EQ(map.AddSensor("laser", laser), MapStatus::kOk);
  const float point[3] = {0.0f, 0.0f, static_cast<float>(range_m)};
  EXPECT_EQ(map.Integrate("laser", Eigen::Isometry3d::Identity(), point, 1), MapStatus::kOk);
  EXPECT_EQ(map.Render("laser"), MapStatus::kOk);
  std::vector<std::optional<double>> out;
  for (const double z : at_m) out.push_back(map.Occupancy(Eigen::Vector3d(0.0, 0.0, z)));
  return out;
}

// A laser's prior (5 m, map.beam_prior_length_m; docs/sensors.md) or longer: a return at 20 m
// marks its surface and clears its beam.
TEST(FarReturnTest, OneReadingAtTwentyMetresMarksAndClears) {
  const std::vector<double> at = {20.0, 21.0, 0.5, 1.0, 5.0, 10.0, 15.0, 19.5};
  for (const double prior_m : {5.0, 30.0}) {
    const auto p = OccupancyAlongTheAxis(prior_m, 20.0, at);
    ASSERT_TRUE(p[0].has_value()) << prior_m;
    EXPECT_GE(*p[0], 0.7) << prior_m;
    // Behind the surface nothing is claimed free.
    EXPECT_TRUE(!p[1].has_value() || *p[1] > 0.45) << prior_m;
    for (std::size_t i = 2; i < at.size(); ++i) {
      ASSERT_TRUE(p[i].has_value()) << prior_m << " m prior, " << at[i];
      EXPECT_LE(*p[i], 0.1) << prior_m << " m prior: not free at " << at[i];
    }
  }
}

// With the default 1 m prior a 20 m return is mostly explained as an
// outlier of a nearer surface: it neither marks its surface nor clears the first metres of
// its beam; a return at 5 m clears its beam.
TEST(FarReturnTest, TheDefaultPriorLeavesAFarReturnUncertain) {
  const double default_m = WorldMapOptions::kDefaultBeamPriorLengthM;
  const auto far = OccupancyAlongTheAxis(default_m, 20.0, {20.0, 2.0});
  ASSERT_TRUE(far[0].has_value() && far[1].has_value());
  EXPECT_LT(*far[0], 0.55);
  EXPECT_GT(*far[1], 0.45);
  const auto near = OccupancyAlongTheAxis(default_m, 5.0, {2.0, 5.0});
  ASSERT_TRUE(near[0].has_value() && near[1].has_value());
  EXPECT_LE(*near[0], 0.1);
  EXPECT_GE(*near[1], 0.55);
}

// The laser_3d preset brings its own 5 m prior: on a map left at the default it marks and
// clears as above, where a sensor with the map's prior (0) does neither.
TEST(FarReturnTest, TheLaserPresetBringsItsOwnPrior) {
  const double preset_m = SensorPreset("laser_3d")->beam_prior_length_m;
  EXPECT_EQ(preset_m, 5.0);
  const double default_m = WorldMapOptions::kDefaultBeamPriorLengthM;
  const auto own = OccupancyAlongTheAxis(default_m, 20.0, {20.0, 2.0}, preset_m);
  ASSERT_TRUE(own[0].has_value() && own[1].has_value());
  EXPECT_GE(*own[0], 0.7);
  EXPECT_LE(*own[1], 0.1);
  const auto maps = OccupancyAlongTheAxis(default_m, 20.0, {20.0, 2.0}, 0.0);
  ASSERT_TRUE(maps[0].has_value() && maps[1].has_value());
  EXPECT_LT(*maps[0], 0.55);
  EXPECT_GT(*maps[1], 0.45);
}

TEST(FarReturnTest, ASensorsPriorMustBeZeroOrInRange) {
  SensorSpec laser = *SensorPreset("laser_3d");
  for (const double bad : {-1.0, 1001.0, std::nan("")}) {
    laser.beam_prior_length_m = bad;
    EXPECT_NE(ValidateSensorSpec(laser).find("beam_prior_length_m"), std::string::npos) << bad;
  }
  laser.beam_prior_length_m = 0.0;
  EXPECT_EQ(ValidateSensorSpec(laser), "");
}

}  // namespace
}  // namespace fusion
