// --print-sensor's estimates (sensor_block.h) on synthetic clouds of known geometry: pinhole
// intrinsics of an organized cloud, angular extents and spacing of scans, the printed blocks
// parsed back as fusiond's configuration.
#include "fusion/clients/sensor_block.h"

#include <google/protobuf/text_format.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>

#include "fusion/clients/importers.h"
#include "fusion/v1/config.pb.h"

namespace fusion::clients {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

double Rad(double deg) { return deg * kPi / 180; }

// An organized width x height cloud of a pinhole camera looking at a slanted wall (depth 1.5 to
// about 3.4 m), every 7th pixel missing.
fusion::v1::RecordedCloud PinholeCloud(double fx, double fy, double cx, double cy,
                                       std::uint32_t width, std::uint32_t height) {
  fusion::v1::RecordedCloud cloud;
  cloud.set_width(width);
  cloud.set_height(height);
  for (std::uint32_t v = 0; v < height; ++v) {
    for (std::uint32_t u = 0; u < width; ++u) {
      if ((u + v * width) % 7 == 3) {
        AppendPoint(kNaN, kNaN, kNaN, &cloud);
        continue;
      }
      const double z = 1.5 + 0.006 * u + 0.002 * v;
      AppendPoint(static_cast<float>((u - cx) * z / fx), static_cast<float>((v - cy) * z / fy),
                  static_cast<float>(z), &cloud);
    }
  }
  return cloud;
}

// An unorganized scan on a grid of directions (optical frame), ranges 2..9 m.
fusion::v1::RecordedCloud AngularScan(double az_min_deg, double az_max_deg, double az_step_deg,
                                      double el_min_deg, double el_max_deg, double el_step_deg) {
  fusion::v1::RecordedCloud cloud;
  int k = 0;
  for (double el = el_min_deg; el <= el_max_deg + 1e-9; el += el_step_deg) {
    for (double az = az_min_deg; az <= az_max_deg + 1e-9; az += az_step_deg) {
      const double r = 2.0 + (k++ % 71) * 0.1;
      const double horizontal = r * std::cos(Rad(el));
      AppendPoint(static_cast<float>(horizontal * std::sin(Rad(az))),
                  static_cast<float>(-r * std::sin(Rad(el))),
                  static_cast<float>(horizontal * std::cos(Rad(az))), &cloud);
    }
  }
  cloud.set_width(static_cast<std::uint32_t>(cloud.xyz_f32le().size() / 12));
  cloud.set_height(1);
  return cloud;
}

// The printed block, parsed back as fusiond's configuration; its one sensor.
fusion::v1::SensorConfig ParseBack(const std::string& text) {
  fusion::v1::ServiceConfig config;
  EXPECT_TRUE(google::protobuf::TextFormat::ParseFromString(text, &config)) << text;
  EXPECT_EQ(config.sensors_size(), 1) << text;
  return config.sensors_size() == 1 ? config.sensors(0) : fusion::v1::SensorConfig();
}

TEST(PinholeEstimatorTest, RecoversKnownIntrinsicsWithAnOffCentrePrincipalPoint) {
  PinholeEstimator estimator;
  ASSERT_TRUE(estimator.Add(PinholeCloud(575.3, 561.8, 291.4, 268.9, 640, 480)));
  PinholeFit fit;
  const Status s = estimator.Fit(&fit);
  ASSERT_TRUE(s.ok()) << s.message();
  EXPECT_NEAR(fit.fx_px, 575.3, 0.1);
  EXPECT_NEAR(fit.fy_px, 561.8, 0.1);
  EXPECT_NEAR(fit.cx_px, 291.4, 0.1);
  EXPECT_NEAR(fit.cy_px, 268.9, 0.1);
  EXPECT_EQ(fit.width_px, 640u);
  EXPECT_EQ(fit.height_px, 480u);
  EXPECT_EQ(fit.points, 640u * 480 - (640u * 480 + 3) / 7);  // the NaNs (i % 7 == 3) left out
  EXPECT_LT(fit.rms_px, 0.05);
}

TEST(PinholeEstimatorTest, RefusesUnorganizedOtherSizesAndEmptyClouds) {
  PinholeEstimator estimator;
  EXPECT_FALSE(estimator.Add(AngularScan(-10, 10, 1, -5, 5, 1)));
  PinholeFit fit;
  EXPECT_FALSE(estimator.Fit(&fit).ok()) << "nothing added";
  ASSERT_TRUE(estimator.Add(PinholeCloud(500, 500, 80, 60, 160, 120)));
  EXPECT_FALSE(estimator.Add(PinholeCloud(500, 500, 80, 60, 320, 240)));
  EXPECT_TRUE(estimator.Fit(&fit).ok());
  EXPECT_NEAR(fit.cx_px, 80, 0.1);
}

TEST(AngularEstimatorTest, ExtentsWidenedByOneBeamAndStepsOfTheData) {
  AngularEstimator estimator;
  // 0.5 deg across, 1 deg down: an anisotropic grid, off-centre in both directions.
  estimator.Add(AngularScan(-60, 45, 0.5, -10, 20, 1.0));
  AngularGrid grid;
  const Status s = estimator.Fit(&grid);
  ASSERT_TRUE(s.ok()) << s.message();
  EXPECT_NEAR(grid.azimuth_step_deg, 0.5, 0.05);
  EXPECT_NEAR(grid.elevation_step_deg, 1.0, 0.1);
  EXPECT_NEAR(grid.azimuth_min_deg, -60.5, 0.11);
  EXPECT_NEAR(grid.azimuth_max_deg, 45.5, 0.11);
  EXPECT_NEAR(grid.elevation_min_deg, -11, 0.21);
  EXPECT_NEAR(grid.elevation_max_deg, 21, 0.21);
  EXPECT_NEAR(grid.cols, 212, 10);
  EXPECT_NEAR(grid.rows, 32, 3);
  EXPECT_EQ(grid.returns_per_scan, 211u * 31);
}

TEST(AngularEstimatorTest, CrowdedScanLinesDoNotOversample) {
  // Scan lines in pairs 0.05 deg apart, a pair every 1 deg: the closest spacing is 20 times
  // finer than the data's, but the grid keeps about one beam per return.
  fusion::v1::RecordedCloud cloud = AngularScan(-30, 30, 0.5, 0, 20, 1);
  const auto second = AngularScan(-30, 30, 0.5, 0.05, 20.05, 1);
  cloud.mutable_xyz_f32le()->append(second.xyz_f32le());
  const double returns = static_cast<double>(cloud.xyz_f32le().size() / 12);
  AngularEstimator estimator;
  estimator.Add(cloud);
  AngularGrid grid;
  ASSERT_TRUE(estimator.Fit(&grid).ok());
  const double beams = static_cast<double>(grid.cols) * grid.rows;
  EXPECT_GE(beams, 0.5 * returns);
  EXPECT_LE(beams, 2.0 * returns);
}

TEST(AngularEstimatorTest, SparseReturnsGetAtMostFourBeamsEach) {
  // Two dense patches in opposite corners of a 100 x 60 deg field of view.
  fusion::v1::RecordedCloud cloud = AngularScan(-50, -45, 0.1, -30, -25, 0.1);
  cloud.mutable_xyz_f32le()->append(AngularScan(45, 50, 0.1, 25, 30, 0.1).xyz_f32le());
  AngularEstimator estimator;
  estimator.Add(cloud);
  AngularGrid grid;
  ASSERT_TRUE(estimator.Fit(&grid).ok());
  EXPECT_LE(static_cast<double>(grid.cols) * grid.rows, 4.0 * (cloud.xyz_f32le().size() / 12));
  EXPECT_LE(grid.azimuth_min_deg, -50);
  EXPECT_GE(grid.elevation_max_deg, 30);
}

TEST(AngularEstimatorTest, PlanarScanKeepsItsStepAcross) {
  AngularEstimator estimator;
  estimator.Add(AngularScan(-90, 90, 0.5, 0, 0, 1));  // one row: a 2D scanner
  AngularGrid grid;
  ASSERT_TRUE(estimator.Fit(&grid).ok());
  EXPECT_NEAR(grid.azimuth_step_deg, 0.5, 1e-6);
  EXPECT_NEAR(grid.cols, 362, 1);
  EXPECT_LE(grid.rows, 2u);
  EXPECT_LT(grid.elevation_min_deg, 0);
  EXPECT_GT(grid.elevation_max_deg, 0);
}

TEST(AngularEstimatorTest, OneDirectionIsAnError) {
  fusion::v1::RecordedCloud cloud;
  AppendPoint(0, 0, 1, &cloud);
  AppendPoint(0, 0, 2, &cloud);
  AngularEstimator estimator;
  estimator.Add(cloud);
  AngularGrid grid;
  EXPECT_FALSE(estimator.Fit(&grid).ok());
}

TEST(SensorBlockTest, RangesAreRoundedOut) {
  fusion::v1::RecordedCloud cloud;
  AppendPoint(0, 0, 0.47f, &cloud);
  AppendPoint(29.04f, 0, 0, &cloud);
  AppendPoint(kNaN, kNaN, kNaN, &cloud);
  RangeSeen ranges;
  ranges.Add(cloud);
  fusion::v1::SensorConfig sensor;
  SetRangesRoundedOut(ranges, &sensor);
  EXPECT_DOUBLE_EQ(sensor.r_min_m(), 0.4);
  EXPECT_DOUBLE_EQ(sensor.r_max_m(), 29.1);
  ranges.min_m = 0.047;
  SetRangesRoundedOut(ranges, &sensor);
  EXPECT_DOUBLE_EQ(sensor.r_min_m(), 0.04);
}

TEST(SensorBlockTest, OrganizedPinholeCloudPrintsAPinholeBlockThatParses) {
  const auto cloud = PinholeCloud(410.2, 409.7, 170.6, 101.3, 320, 240);
  double farthest_m = 0;
  for (std::size_t i = 0; i < cloud.xyz_f32le().size() / 12; ++i) {
    float p[3];
    GetPoint(cloud, i, p);
    if (std::isfinite(p[0]))
      farthest_m = std::max(farthest_m, std::hypot(double{p[0]}, double{p[1]}, double{p[2]}));
  }
  ImportedGeometry geometry;
  geometry.Add(cloud);
  fusion::v1::SensorConfig sensor;
  std::string notes;
  ASSERT_TRUE(geometry.Describe("cam", "", &sensor, &notes).ok());
  EXPECT_NE(notes.find("q_mu"), std::string::npos) << notes;
  const std::string text = SensorBlockText(sensor);
  EXPECT_EQ(text.rfind("sensors {", 0), 0u) << text;
  const auto parsed = ParseBack(text);
  EXPECT_EQ(parsed.id(), "cam");
  EXPECT_TRUE(parsed.preset().empty());
  EXPECT_NEAR(parsed.pinhole().fx(), 410.2, 0.1);
  EXPECT_NEAR(parsed.pinhole().fy(), 409.7, 0.1);
  EXPECT_NEAR(parsed.pinhole().cx(), 170.6, 0.1);
  EXPECT_NEAR(parsed.pinhole().cy(), 101.3, 0.1);
  EXPECT_EQ(parsed.pinhole().width(), 320u);
  EXPECT_EQ(parsed.pinhole().height(), 240u);
  EXPECT_EQ(parsed.pinhole().stride(), 1u);
  EXPECT_GE(parsed.r_min_m(), 1.5);  // depth 1.5 m at pixel (0, 0), 1.62 m away
  EXPECT_LE(parsed.r_min_m(), 1.7);
  EXPECT_GE(parsed.r_max_m(), farthest_m);
  EXPECT_LT(parsed.r_max_m(), farthest_m + 0.1);
  EXPECT_FALSE(parsed.has_cols());
  EXPECT_FALSE(parsed.has_azimuth_min_deg());
}

TEST(SensorBlockTest, ScanPrintsTheAngularFormThatParses) {
  ImportedGeometry geometry;
  geometry.Add(AngularScan(-90, 90, 1, -7, 32, 0.5));
  fusion::v1::SensorConfig sensor;
  std::string notes;
  ASSERT_TRUE(geometry.Describe("scanner", "laser_3d", &sensor, &notes).ok());
  const auto parsed = ParseBack(SensorBlockText(sensor));
  EXPECT_EQ(parsed.id(), "scanner");
  EXPECT_EQ(parsed.preset(), "laser_3d");
  EXPECT_NEAR(parsed.azimuth_min_deg(), -91, 0.11);
  EXPECT_NEAR(parsed.azimuth_max_deg(), 91, 0.11);
  EXPECT_NEAR(parsed.elevation_min_deg(), -7.5, 0.11);
  EXPECT_NEAR(parsed.elevation_max_deg(), 32.5, 0.11);
  EXPECT_NEAR(parsed.cols(), 182, 9);
  EXPECT_NEAR(parsed.rows(), 80, 4);
  EXPECT_GE(parsed.r_min_m(), 1.9);  // 2.0 m, or 1.9 if a float lands a hair below it
  EXPECT_LE(parsed.r_min_m(), 2.0);
  EXPECT_GE(parsed.r_max_m(), 9.0);
  EXPECT_LE(parsed.r_max_m(), 9.1);
  EXPECT_FALSE(parsed.has_pinhole());
}

TEST(SensorBlockTest, OrganizedCloudThatIsNoPinholeCameraGetsTheAngularForm) {
  // An organized 360 x 10 spinning-lidar-like grid: rows of elevation, columns of azimuth.
  fusion::v1::RecordedCloud cloud = AngularScan(-179, 180, 1, -5, 4, 1);
  cloud.set_width(360);
  cloud.set_height(10);
  ImportedGeometry geometry;
  geometry.Add(cloud);
  fusion::v1::SensorConfig sensor;
  std::string notes;
  ASSERT_TRUE(geometry.Describe("lidar", "", &sensor, &notes).ok());
  EXPECT_FALSE(sensor.has_pinhole()) << notes;
  EXPECT_GE(sensor.azimuth_max_deg() - sensor.azimuth_min_deg(), 359);
  EXPECT_LE(sensor.azimuth_max_deg(), 180);
  EXPECT_GE(sensor.azimuth_min_deg(), -180);
}

TEST(SensorBlockTest, TumBlockHasThePresetIntrinsicsAndStride) {
  TumOptions options;
  options.sensor_id = "kinect";
  options.stride = 4;
  const auto parsed = ParseBack(SensorBlockText(TumSensorConfig(options, {640, 480})));
  EXPECT_EQ(parsed.id(), "kinect");
  EXPECT_EQ(parsed.preset(), "kinect_v1");
  EXPECT_DOUBLE_EQ(parsed.pinhole().fx(), 520.9);
  EXPECT_DOUBLE_EQ(parsed.pinhole().fy(), 521.0);
  EXPECT_DOUBLE_EQ(parsed.pinhole().cx(), 325.1);
  EXPECT_DOUBLE_EQ(parsed.pinhole().cy(), 249.7);
  EXPECT_EQ(parsed.pinhole().width(), 640u);
  EXPECT_EQ(parsed.pinhole().height(), 480u);
  EXPECT_EQ(parsed.pinhole().stride(), 4u);
  EXPECT_FALSE(parsed.has_r_min_m());
}

}  // namespace
}  // namespace fusion::clients
