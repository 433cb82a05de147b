// End to end with a real 3D laser scan: OctoMap's sample scan (88,206 points in the scanner
// frame: x forward, y left, z up; 180 degrees sideways, -7..+32 degrees up, 0.47..29 m)
// imported with fusion-import scan --frame body and the scanner's --pose, replayed into a
// fusiond process with a 184 x 66 degree sensor of 0.5 degree beams, and queried over gRPC:
// voxels at the points are occupied, half-way to them free.
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <memory>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "../support/e2e_service.h"
#include "fusion/v1/map_service.grpc.pb.h"
#include "fusion/v1/recording.pb.h"

namespace {

using fusion::testing::E2eService;
using fusion::testing::ReadRecording;
using fusion::testing::RunTool;
using fusion::testing::Subprocess;
using fusion::testing::WorldPoints;
using namespace std::chrono_literals;
namespace v1 = fusion::v1;
namespace fs = std::filesystem;

const std::string kScan = std::string(FUSION_SHARED_DATA_DIR) + "/octomap_laser_scan/scan.dat.bz2";

// The scan's points (scanner frame), through bzip2 -dc.
std::vector<Eigen::Vector3d> ReadScan(const std::string& path) {
  std::vector<Eigen::Vector3d> points;
  FILE* pipe = popen(("bzip2 -dc '" + path + "'").c_str(), "r");
  if (pipe == nullptr) return points;
  double x = 0, y = 0, z = 0;
  while (std::fscanf(pipe, "%lf %lf %lf", &x, &y, &z) == 3) points.emplace_back(x, y, z);
  pclose(pipe);
  return points;
}

std::size_t CountState(const std::vector<v1::PointOccupancy>& results, v1::VoxelState state) {
  return static_cast<std::size_t>(std::count_if(results.begin(), results.end(),
                                                [&](const auto& r) { return r.state() == state; }));
}

// The scanner's axes, from the data: x forward (azimuth atan2(y, x) spans -91..+91 deg, x
// from -0.08 to 27 m), y left, z up (elevation -7..+32 deg, the ground at z ~ -0.1 m): the
// body frame of --frame body. The scanner is at kScannerInWorld = (1, 2, 0.5) in the world
// (axes as the scanner's), so the recorded pose of the optical frame (x_o = -y_s, y_o = -z_s,
// z_o = x_s) is that rotation: q = (-0.5, 0.5, -0.5, 0.5).
const Eigen::Vector3d kScannerInWorld(1.0, 2.0, 0.5);

class E2eLaserScanTest : public E2eService {
 protected:
  void SetUp() override {
    if (!fs::exists(kScan)) {
      GTEST_SKIP() << "OctoMap laser scan missing: " << kScan
                   << " (see ../shared/data/README.md: octomap_laser_scan)";
    }
    E2eService::SetUp();
  }

  // The steps of PointsAreOccupiedAndRaysFree; the test calls each in ASSERT_NO_FATAL_FAILURE,
  // so that a failed ASSERT in a step ends the test as it did when the steps were inline.

  // The scan file (scanner frame) imported with --frame body and the scanner's pose into
  // `recording`; *world: the recording's points in the world frame.
  // *sensor_block: the `sensors { ... }` block the importer prints for the scan.
  void ImportTheScan(const std::vector<Eigen::Vector3d>& scan, const std::string& recording,
                     std::vector<Eigen::Vector3d>* world, std::string* sensor_block) {
    const Eigen::Vector3d& t = kScannerInWorld;
    std::ostringstream pose;
    pose.precision(17);
    pose << t.x() << ',' << t.y() << ',' << t.z();
    ASSERT_EQ(RunTool({"fusion-import", "scan", kScan, "--frame", "body", "--pose", pose.str(),
                       "--sensor-id", "scanner", "--print-sensor", "-o", recording},
                      sensor_block),
              0)
        << *sensor_block;
    ASSERT_NE(sensor_block->find("preset: \"laser_3d\""), std::string::npos) << *sensor_block;
    const auto clouds = ReadRecording(recording);
    ASSERT_EQ(clouds.size(), 1u);
    const auto& q = clouds[0].t_world_sensor();
    ASSERT_NEAR(std::abs(q.qx()), 0.5, 1e-12);  // (-0.5, 0.5, -0.5, 0.5) or its negation
    ASSERT_NEAR(q.qx() * q.qw(), -0.25, 1e-12);
    ASSERT_NEAR(q.qy() * q.qw(), 0.25, 1e-12);
    ASSERT_NEAR(q.qz() * q.qw(), -0.25, 1e-12);
    *world = WorldPoints(clouds[0]);
    ASSERT_EQ(world->size(), scan.size());
    // The recording's pose puts every point back where the scanner saw it (+ t).
    for (std::size_t i = 0; i < scan.size(); i += 1000) {
      ASSERT_LT(((*world)[i] - (scan[i] + t)).norm(), 1e-4) << i;
    }
  }

  // fusiond configured with the block the importer printed (the laser_3d preset over the
  // scan's own field of view and beams), a 0.15 m map. The recording replayed into it; every
  // point used: import, configure and replay without describing the sensor by hand.
  void ReplayIntoFusiond(const std::string& recording, const std::string& sensor_block,
                         std::size_t point_count) {
    std::ostringstream config;
    config << "log_level: \"warn\"\n"
           << sensor_block
           << "map { resolution_m: 0.15 render_interval_ms: 100 beam_cell_size_m: 0.02 }\n"
           << "ingest { reliability: \"reliable\" }\n";
    ASSERT_NO_FATAL_FAILURE(StartFusiond(config.str()));
    const auto start = std::chrono::steady_clock::now();
    std::string out;
    ASSERT_EQ(RunTool({"fusion-replay", recording, "--domain", std::to_string(domain_), "--fast",
                       "--reliable", "--quiet"},
                      &out),
              0)
        << out;
    ASSERT_TRUE(WaitInMap(1, 60s));
    std::printf("integrated and rendered in %.1f s\n",
                std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
    const auto counters = Counters("scanner");
    EXPECT_EQ(counters.points_updated(), point_count) << counters.ShortDebugString();
    EXPECT_EQ(counters.points_rejected(), 0u) << "the fan lies in the field of view";
  }

  // Occupied at the points (a sample of 1 in 10), free half-way from the scanner to them.
  void ExpectOccupiedAtThePointsFreeOnTheRays(const std::vector<Eigen::Vector3d>& scan,
                                              const std::vector<Eigen::Vector3d>& world) {
    const Eigen::Vector3d& t = kScannerInWorld;
    std::vector<Eigen::Vector3d> sample, half_way;
    for (std::size_t i = 0; i < world.size(); i += 10) {
      sample.push_back(world[i]);
      if (scan[i].norm() > 2.0) half_way.push_back(t + 0.5 * scan[i]);
    }
    const auto at_points = Query(sample);
    const auto on_rays = Query(half_way);
    ASSERT_EQ(at_points.size(), sample.size());
    ASSERT_EQ(on_rays.size(), half_way.size());
    const double occupied = double(CountState(at_points, v1::VOXEL_STATE_OCCUPIED)) / sample.size();
    const double free = double(CountState(on_rays, v1::VOXEL_STATE_FREE)) / half_way.size();
    std::printf("%zu points: %.1f%% occupied; %zu half-way points: %.1f%% free\n", sample.size(),
                100 * occupied, half_way.size(), 100 * free);
    EXPECT_GE(occupied, 0.8) << sample.size() << " points";
    EXPECT_GE(free, 0.8) << half_way.size() << " half-way points";
  }
};

TEST_F(E2eLaserScanTest, PointsAreOccupiedAndRaysFree) {
  const auto scan = ReadScan(kScan);
  ASSERT_EQ(scan.size(), 88206u) << "bzip2 -dc " << kScan;
  const std::string recording = dir_ + "/scan.frec";
  std::vector<Eigen::Vector3d> world;
  std::string sensor_block;
  ASSERT_NO_FATAL_FAILURE(ImportTheScan(scan, recording, &world, &sensor_block));
  ASSERT_NO_FATAL_FAILURE(ReplayIntoFusiond(recording, sensor_block, scan.size()));
  ASSERT_NO_FATAL_FAILURE(ExpectOccupiedAtThePointsFreeOnTheRays(scan, world));
  // Behind the scanner (x < -0.5 in the scanner frame) nothing was seen.
  const Eigen::Vector3d& t = kScannerInWorld;
  const auto behind = Query({t + Eigen::Vector3d(-2, 0, 0.5), t + Eigen::Vector3d(-5, 3, 1)});
  EXPECT_EQ(CountState(behind, v1::VOXEL_STATE_UNKNOWN), 2u);

  EXPECT_EQ(fusiond_->Stop(SIGTERM, 10000ms), 0);
}

}  // namespace
