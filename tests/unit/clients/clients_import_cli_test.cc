// fusion-import run as a process: --frame body with a rotated --pose puts the points at R p + t,
// --print-sensor prints only a sensors { ... } block on stdout that parses as fusiond's
// configuration, for synthetic files and (skipped when absent) the real data.
#include <google/protobuf/text_format.h>
#include <gtest/gtest.h>
#include <octomap/ScanGraph.h>

#include <array>
#include <chrono>
#include <cmath>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include "../../support/subprocess.h"
#include "fusion/clients/importers.h"
#include "fusion/clients/recording.h"
#include "fusion/v1/config.pb.h"
#include "import_test_util.h"

namespace fusion::clients::import_test {
namespace {

constexpr double kPi = 3.14159265358979323846;

// Runs build/clients/fusion-import with `args`; returns the exit code and *out its stdout.
int RunImport(const std::vector<std::string>& args, std::string* out) {
  std::vector<std::string> argv{std::string(FUSION_BINARY_DIR) + "/clients/fusion-import"};
  argv.insert(argv.end(), args.begin(), args.end());
  fusion::testing::Subprocess process(argv);
  if (!process.started()) return -1;
  process.WaitForOutput("(?!)", std::chrono::seconds(60));  // until stdout closes
  const int code = process.Wait(std::chrono::milliseconds(5000));
  *out = process.output();
  return code;
}

// stdout parsed as fusiond's configuration: exactly one sensor, nothing else.
fusion::v1::SensorConfig ParseSensor(const std::string& out) {
  EXPECT_EQ(out.rfind("sensors {", 0), 0u) << out;
  fusion::v1::ServiceConfig config;
  EXPECT_TRUE(google::protobuf::TextFormat::ParseFromString(out, &config)) << out;
  EXPECT_EQ(config.sensors_size(), 1) << out;
  fusion::v1::ServiceConfig only_sensors;
  *only_sensors.mutable_sensors() = config.sensors();
  EXPECT_EQ(config.SerializeAsString(), only_sensors.SerializeAsString()) << out;
  return config.sensors_size() == 1 ? config.sensors(0) : fusion::v1::SensorConfig();
}

std::vector<fusion::v1::RecordedCloud> ReadClouds(const std::string& path) {
  std::unique_ptr<RecordingReader> reader;
  std::vector<fusion::v1::RecordedCloud> clouds;
  if (!RecordingReader::Open(path, &reader).ok()) return clouds;
  for (std::size_t i = 0; i < reader->size(); ++i) {
    clouds.emplace_back();
    if (!reader->Read(i, &clouds.back()).ok()) clouds.pop_back();
  }
  return clouds;
}

// Rz(yaw) p + t, the expected world point of a body point.
std::array<double, 3> YawThenMove(double yaw, const double t[3], const std::array<double, 3>& p) {
  return {std::cos(yaw) * p[0] - std::sin(yaw) * p[1] + t[0],
          std::sin(yaw) * p[0] + std::cos(yaw) * p[1] + t[1], p[2] + t[2]};
}

void ExpectWorldPoints(const fusion::v1::RecordedCloud& cloud,
                       const std::vector<std::array<double, 3>>& expected) {
  ASSERT_EQ(cloud.xyz_f32le().size() / 12, expected.size());
  for (std::size_t i = 0; i < expected.size(); ++i) {
    float p[3];
    GetPoint(cloud, i, p);
    double world[3];
    ToWorld(cloud.t_world_sensor(), p, world);
    for (int a = 0; a < 3; ++a) ASSERT_NEAR(world[a], expected[i][a], 1e-4) << i << ", " << a;
  }
}

// A fan of returns in the body frame: 40 deg left and right, -5..+10 deg up, 5 m away.
std::vector<std::array<double, 3>> BodyFan() {
  std::vector<std::array<double, 3>> points;
  for (double el = -5; el <= 10 + 1e-9; el += 0.5) {
    for (double az = -40; az <= 40 + 1e-9; az += 1) {
      const double a = az * kPi / 180, e = el * kPi / 180;
      points.push_back(
          {5 * std::cos(e) * std::cos(a), 5 * std::cos(e) * std::sin(a), 5 * std::sin(e)});
    }
  }
  return points;
}

TEST(ImportCliTest, ScanInTheBodyFrameWithARotatedPose) {
  const auto body = BodyFan();
  std::ostringstream text;
  text.precision(9);
  for (const auto& p : body) text << p[0] << ' ' << p[1] << ' ' << p[2] << '\n';
  const std::string scan = TempPath("cli_fan.txt"), recording = TempPath("cli_fan.frec");
  WriteFile(scan, text.str());
  const double yaw = kPi / 4, t[3] = {1, 2, 0.5};
  std::string out;
  ASSERT_EQ(RunImport({"scan", scan, "--frame", "body", "--pose",
                       "1,2,0.5,0,0," + std::to_string(std::sin(yaw / 2)) + "," +
                           std::to_string(std::cos(yaw / 2)),
                       "--print-sensor", "--sensor-id", "fan", "-o", recording},
                      &out),
            0);
  const auto sensor = ParseSensor(out);
  EXPECT_EQ(sensor.id(), "fan");
  EXPECT_EQ(sensor.preset(), "laser_3d");
  EXPECT_NEAR(sensor.azimuth_min_deg(), -41, 0.11);
  EXPECT_NEAR(sensor.azimuth_max_deg(), 41, 0.11);
  EXPECT_NEAR(sensor.elevation_min_deg(), -5.5, 0.11);  // up in the body is up in the block
  EXPECT_NEAR(sensor.elevation_max_deg(), 10.5, 0.11);
  EXPECT_NEAR(sensor.cols(), 82, 4);
  EXPECT_NEAR(sensor.rows(), 32, 2);
  EXPECT_DOUBLE_EQ(sensor.r_min_m(), 4.9);
  EXPECT_DOUBLE_EQ(sensor.r_max_m(), 5.1);

  const auto clouds = ReadClouds(recording);
  ASSERT_EQ(clouds.size(), 1u);
  std::vector<std::array<double, 3>> expected;
  for (const auto& p : body) expected.push_back(YawThenMove(yaw, t, p));
  ExpectWorldPoints(clouds[0], expected);
  float ahead[3];  // azimuth 0, elevation 0: 5 m forward, stored in the optical frame
  GetPoint(clouds[0], 10 * 81 + 40, ahead);
  EXPECT_NEAR(ahead[0], 0, 1e-6);
  EXPECT_NEAR(ahead[1], 0, 1e-6);
  EXPECT_NEAR(ahead[2], 5, 1e-6);
  std::remove(scan.c_str());
  std::remove(recording.c_str());
}

TEST(ImportCliTest, BadFramesAndTheDefaultOutput) {
  const std::string scan = TempPath("cli_small.txt"), recording = TempPath("cli_small.frec");
  WriteFile(scan, "0 0 1\n0.1 0 1\n");
  std::string out;
  EXPECT_EQ(RunImport({"scan", scan, "--frame", "robot", "-o", recording}, &out), 2);
  EXPECT_EQ(RunImport({"pcd", scan, "--frame", "body", "-o", recording}, &out), 2);
  EXPECT_EQ(RunImport({"tum", scan, "--frame", "body", "-o", recording}, &out), 2);
  // Without --print-sensor stdout says what was imported, as before.
  ASSERT_EQ(RunImport({"scan", scan, "-o", recording}, &out), 0);
  EXPECT_EQ(out.rfind("imported 1 clouds (2 points)", 0), 0u) << out;
  std::remove(scan.c_str());
  std::remove(recording.c_str());
}

TEST(ImportCliTest, OrganizedPcdPrintsTheFittedPinhole) {
  const double fx = 70.5, fy = 69.5, cx = 30.2, cy = 25.8;
  std::ostringstream pcd;
  pcd << "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 64\nHEIGHT 48\n"
      << "VIEWPOINT 0 0 0 1 0 0 0\nPOINTS 3072\nDATA ascii\n";
  pcd.precision(9);
  for (int v = 0; v < 48; ++v) {
    for (int u = 0; u < 64; ++u) {
      const double z = 1.0 + 0.01 * u;
      pcd << (u - cx) * z / fx << ' ' << (v - cy) * z / fy << ' ' << z << '\n';
    }
  }
  const std::string path = TempPath("cli_cam.pcd"), recording = TempPath("cli_cam.frec");
  WriteFile(path, pcd.str());
  std::string out;
  ASSERT_EQ(RunImport({"pcd", path, "--print-sensor", "-o", recording}, &out), 0);
  const auto sensor = ParseSensor(out);
  EXPECT_EQ(sensor.id(), "pcd");
  EXPECT_NEAR(sensor.pinhole().fx(), fx, 0.1);
  EXPECT_NEAR(sensor.pinhole().fy(), fy, 0.1);
  EXPECT_NEAR(sensor.pinhole().cx(), cx, 0.1);
  EXPECT_NEAR(sensor.pinhole().cy(), cy, 0.1);
  EXPECT_EQ(sensor.pinhole().width(), 64u);
  EXPECT_EQ(sensor.pinhole().height(), 48u);
  EXPECT_EQ(sensor.pinhole().stride(), 1u);
  std::remove(path.c_str());
  std::remove(recording.c_str());
}

TEST(ImportCliTest, GraphOfBodyScans) {
  octomap::ScanGraph graph;
  auto* scan = new octomap::Pointcloud();  // the graph owns it
  scan->push_back(3, 0, 0);
  scan->push_back(0, 1, 0.5);
  graph.addNode(scan, octomap::pose6d(2, 0, 1, 0, 0, kPi / 2));
  const std::string path = TempPath("cli_body.graph"), recording = TempPath("cli_body.frec");
  ASSERT_TRUE(graph.writeBinary(path));
  std::string out;
  ASSERT_EQ(RunImport({"graph", path, "--frame", "body", "--print-sensor", "-o", recording}, &out),
            0);
  const auto sensor = ParseSensor(out);
  EXPECT_EQ(sensor.preset(), "laser_3d");
  EXPECT_EQ(sensor.id(), "scanner");
  EXPECT_LT(sensor.azimuth_min_deg(), -90);   // the point 1 m to the left, optical azimuth -90
  EXPECT_GT(sensor.elevation_max_deg(), 26);  // atan2(0.5, 1)
  const auto clouds = ReadClouds(recording);
  ASSERT_EQ(clouds.size(), 1u);
  const double t[3] = {2, 0, 1};
  ExpectWorldPoints(clouds[0],
                    {YawThenMove(kPi / 2, t, {3, 0, 0}), YawThenMove(kPi / 2, t, {0, 1, 0.5})});
  std::remove(path.c_str());
  std::remove(recording.c_str());
}

TEST(ImportCliTest, RealTumAtStride4PrintsTheKinectBlock) {
  const std::string dir = kData + "/tum_fr2_pioneer_slam2";
  if (!Exists(dir + "/groundtruth.txt")) GTEST_SKIP() << "TUM data not found at " << dir;
  const std::string recording = TempPath("cli_tum.frec");
  std::string out;
  ASSERT_EQ(RunImport({"tum", dir, "--stride", "4", "--print-sensor", "-o", recording}, &out), 0);
  const auto sensor = ParseSensor(out);
  EXPECT_EQ(sensor.id(), "tum");
  EXPECT_EQ(sensor.preset(), "kinect_v1");
  EXPECT_DOUBLE_EQ(sensor.pinhole().fx(), 520.9);
  EXPECT_DOUBLE_EQ(sensor.pinhole().cy(), 249.7);
  EXPECT_EQ(sensor.pinhole().width(), 640u);
  EXPECT_EQ(sensor.pinhole().height(), 480u);
  EXPECT_EQ(sensor.pinhole().stride(), 4u);
  std::remove(recording.c_str());
}

TEST(ImportCliTest, RealLaserScanPrintsItsFieldOfView) {
  const std::string path = kData + "/octomap_laser_scan/scan.dat.bz2";
  if (!Exists(path)) GTEST_SKIP() << "OctoMap scan not found at " << path;
  const std::string recording = TempPath("cli_laser.frec");
  std::string out;
  ASSERT_EQ(RunImport({"scan", path, "--frame", "body", "--print-sensor", "-o", recording}, &out),
            0);
  const auto sensor = ParseSensor(out);
  EXPECT_EQ(sensor.preset(), "laser_3d");
  // README: 180 degrees sideways (-91..+91 in the data), about -7..+32 degrees up.
  EXPECT_LT(sensor.azimuth_min_deg(), -90.9);
  EXPECT_GT(sensor.azimuth_max_deg(), 90.9);
  EXPECT_GT(sensor.azimuth_min_deg(), -93);
  EXPECT_LT(sensor.elevation_min_deg(), -6.9);
  EXPECT_GT(sensor.elevation_min_deg(), -9);
  EXPECT_GT(sensor.elevation_max_deg(), 31.6);
  EXPECT_LT(sensor.elevation_max_deg(), 34);
  const double beams = static_cast<double>(sensor.cols()) * sensor.rows();
  EXPECT_GE(beams, 88206);
  EXPECT_LE(beams, 4 * 88206);
  EXPECT_DOUBLE_EQ(sensor.r_min_m(), 0.4);  // 0.47..29 m
  EXPECT_GE(sensor.r_max_m(), 29.0);
  EXPECT_LE(sensor.r_max_m(), 29.5);
  std::remove(recording.c_str());
}

}  // namespace
}  // namespace fusion::clients::import_test
