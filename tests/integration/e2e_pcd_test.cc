// End to end with a real stereo frame: PCL's table_scene_mug_stereo_textured.pcd (640 x 480,
// camera frame) imported with fusion-import pcd, replayed into a fusiond process (private DDS
// domain, 127.0.0.1:0) with an explicit stereo sensor, and queried over gRPC: voxels at the
// frame's points are occupied, half-way to them free, and the table is the dominant plane.
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

const std::string kPcd =
    std::string(FUSION_SHARED_DATA_DIR) + "/pcl_stereo/table_scene_mug_stereo_textured.pcd";
constexpr double kPi = 3.14159265358979323846;
std::size_t CountState(const std::vector<v1::PointOccupancy>& results, v1::VoxelState state) {
  return static_cast<std::size_t>(std::count_if(results.begin(), results.end(),
                                                [&](const auto& r) { return r.state() == state; }));
}

// Whether a found plane lies within 4 degrees and 3 cm of the expected one (normal `normal`,
// distance d_m from the origin), either way round.
bool PlaneMatches(const v1::Plane& p, const Eigen::Vector3d& normal, double d_m) {
  Eigen::Vector3d n(p.normal().x(), p.normal().y(), p.normal().z());
  double pd = p.d_m();
  if (n.dot(normal) < 0) {
    n = -n;
    pd = -pd;
  }
  return std::acos(std::min(1.0, n.dot(normal))) * 180.0 / kPi < 4.0 && std::abs(pd - d_m) < 0.03;
}

class E2ePcdTest : public E2eService {
 protected:
  void SetUp() override {
    if (!fs::exists(kPcd)) {
      GTEST_SKIP() << "PCL stereo frame missing: " << kPcd
                   << " (see ../shared/data/README.md: pcl_stereo)";
    }
    E2eService::SetUp();
  }

  // The steps of TableIsOccupiedFreeInFrontAndTheDominantPlane; the test calls each in
  // ASSERT_NO_FATAL_FAILURE, so that a failed ASSERT in a step ends the test as it did when
  // the steps were inline.

  // 1. The file's VIEWPOINT (a half turn about x) would put every point behind the camera;
  // the points are in the camera's optical frame already: --ignore-viewpoint keeps them.
  // *recording: the import with --ignore-viewpoint; *points: its points (camera = world).
  void ImportTheFrame(std::string* recording, std::vector<Eigen::Vector3d>* points) {
    const std::string with_viewpoint = dir_ + "/viewpoint.frec";
    *recording = dir_ + "/table.frec";
    std::string out;
    ASSERT_EQ(RunTool({"fusion-import", "pcd", kPcd, "--sensor-id", "stereo", "-o", with_viewpoint},
                      &out),
              0)
        << out;
    ASSERT_EQ(RunTool({"fusion-import", "pcd", "--ignore-viewpoint", kPcd, "--sensor-id", "stereo",
                       "-o", *recording},
                      &out),
              0)
        << out;
    const auto turned = ReadRecording(with_viewpoint);
    const auto clouds = ReadRecording(*recording);
    ASSERT_EQ(turned.size(), 1u);
    ASSERT_EQ(clouds.size(), 1u);
    ASSERT_EQ(clouds[0].width(), 640u);
    ASSERT_EQ(clouds[0].height(), 480u);
    const auto behind = WorldPoints(turned[0]);  // world = the VIEWPOINT pose applied back
    *points = WorldPoints(clouds[0]);            // identity pose: camera frame = world
    ASSERT_GT(points->size(), 200000u);          // 209,280 of 307,200 pixels have a disparity
    std::size_t in_front = 0, behind_in_sensor = 0;
    {
      std::vector<float> xyz(turned[0].xyz_f32le().size() / sizeof(float));
      std::memcpy(xyz.data(), turned[0].xyz_f32le().data(), xyz.size() * sizeof(float));
      for (std::size_t i = 2; i < xyz.size(); i += 3) behind_in_sensor += xyz[i] < 0;
    }
    for (const auto& p : *points) in_front += p.z() > 0;
    EXPECT_EQ(behind_in_sensor, behind.size()) << "with the VIEWPOINT every point is behind";
    EXPECT_EQ(in_front, points->size()) << "without it every point is in front";
  }

  // 2. fusiond with the stereo camera: 640 x 480 pixels of fx ~ 964 px (measured from the
  // points: x/z changes by 1/964 per column) and the principal point near (320, 223): 37 x 30
  // degrees covers every pixel; 160 x 120 beams = 4 x 4 pixels (several samples) per beam.
  // Stereo noise grows with r^2: sigma(r) = 3 mm + 4 mm/m^2 r^2.
  void ReplayIntoFusiond(const std::string& recording, std::size_t point_count) {
    std::ostringstream config;
    config << "log_level: \"warn\"\n"
           << "sensors { id: \"stereo\" model: \"paper3d\" r_min_m: 0.3 r_max_m: 3.0\n"
           << "  fov_h_deg: 37.0 fov_v_deg: 30.0 cols: 160 rows: 120 epsilon: 0.02\n"
           << "  q_mu { a2: 0 a1: 1 a0: 0 } q_sigma { a2: 0.004 a1: 0 a0: 0.003 } }\n"
           << "map { resolution_m: 0.02 render_interval_ms: 100 beam_cell_size_m: 0.005 }\n"
           << "ingest { reliability: \"reliable\" }\n";
    ASSERT_NO_FATAL_FAILURE(StartFusiond(config.str()));
    std::string out;
    ASSERT_EQ(RunTool({"fusion-replay", recording, "--domain", std::to_string(domain_), "--fast",
                       "--reliable", "--quiet"},
                      &out),
              0)
        << out;
    ASSERT_TRUE(WaitInMap(1, 30s));
    const auto counters = Counters("stereo");
    EXPECT_EQ(counters.rejected(), 0u);
    EXPECT_EQ(counters.points_updated(), point_count) << counters.ShortDebugString();
    EXPECT_EQ(counters.points_missing(), 640u * 480u - point_count);
    EXPECT_EQ(counters.points_rejected(), 0u) << "every pixel lies in the field of view";
  }

  // 3. Occupied where the points are, free half-way between the camera and them.
  void ExpectOccupiedAtThePointsFreeHalfWay(const std::vector<Eigen::Vector3d>& points) {
    std::vector<Eigen::Vector3d> sample, half_way;
    for (std::size_t i = 0; i < points.size(); i += 97) {
      sample.push_back(points[i]);
      half_way.push_back(0.5 * points[i]);
    }
    const auto at_points = Query(sample);
    const auto in_front_of = Query(half_way);
    ASSERT_EQ(at_points.size(), sample.size());
    ASSERT_EQ(in_front_of.size(), half_way.size());
    const double occupied = double(CountState(at_points, v1::VOXEL_STATE_OCCUPIED)) / sample.size();
    const double free = double(CountState(in_front_of, v1::VOXEL_STATE_FREE)) / half_way.size();
    std::printf("%zu points: %.1f%% occupied; %zu half-way points: %.1f%% free\n", sample.size(),
                100 * occupied, half_way.size(), 100 * free);
    EXPECT_GE(occupied, 0.8) << sample.size() << " points";
    EXPECT_GE(free, 0.9) << half_way.size() << " points";
    // No point of the sample lies in free space.
    EXPECT_LE(CountState(at_points, v1::VOXEL_STATE_FREE), sample.size() / 50);
  }

  // QueryBox around a patch of the table centre `c`: occupied voxels, and free ones in front.
  void ExpectTheTableCentreInABox(const Eigen::Vector3d& c) {
    v1::QueryBoxRequest box;
    box.mutable_min()->set_x(c.x() - 0.05);
    box.mutable_min()->set_y(c.y() - 0.05);
    box.mutable_min()->set_z(0.4);
    box.mutable_max()->set_x(c.x() + 0.05);
    box.mutable_max()->set_y(c.y() + 0.05);
    box.mutable_max()->set_z(c.z() + 0.05);
    grpc::ClientContext context;
    context.set_deadline(std::chrono::system_clock::now() + 10s);
    v1::QueryBoxResponse reply;
    ASSERT_TRUE(stub_->QueryBox(&context, box, &reply).ok());
    int occupied_near = 0, free_before = 0;
    for (const auto& v : reply.voxels()) {
      if (v.state() == v1::VOXEL_STATE_OCCUPIED && std::abs(v.center().z() - c.z()) < 0.1) {
        ++occupied_near;
      }
      if (v.state() == v1::VOXEL_STATE_FREE && v.center().z() < c.z() - 0.1) ++free_before;
    }
    EXPECT_GT(occupied_near, 0) << "table centre " << c.transpose();
    EXPECT_GT(free_before, 10) << "table centre " << c.transpose();
  }

  // FindPlanes (up to 4) in x, y within +-5 m and z in [0, max_z_m].
  v1::FindPlanesResponse FindPlanesBelow(double max_z_m) {
    grpc::ClientContext context;
    context.set_deadline(std::chrono::system_clock::now() + 20s);
    v1::FindPlanesRequest request;
    request.set_max_planes(4);
    request.mutable_region_min()->set_x(-5);
    request.mutable_region_min()->set_y(-5);
    request.mutable_region_min()->set_z(0);
    request.mutable_region_max()->set_x(5);
    request.mutable_region_max()->set_y(5);
    request.mutable_region_max()->set_z(max_z_m);
    v1::FindPlanesResponse reply;
    const auto status = stub_->FindPlanes(&context, request, &reply);
    EXPECT_TRUE(status.ok()) << status.error_message();
    return reply;
  }

  // 4. Planes. RANSAC on the frame's points: the table, n = (-0.015, 0.848, 0.529), d = 0.513 m
  // (59% of the points within 1 cm), and the wall behind it, n = (-0.052, -0.533, 0.845),
  // d = 1.925 m (a quarter of the points, but 2.5 times farther: more voxels).
  void ExpectTheTableIsTheDominantPlane(const std::vector<Eigen::Vector3d>& points) {
    const Eigen::Vector3d table_normal = Eigen::Vector3d(-0.015, 0.848, 0.529).normalized();
    const Eigen::Vector3d wall_normal = Eigen::Vector3d(-0.052, -0.533, 0.845).normalized();
    const auto everything = FindPlanesBelow(10.0);
    ASSERT_GE(everything.planes_size(), 2) << everything.ShortDebugString();
    // Planes come by votes: the wall first, the table among the next.
    EXPECT_TRUE(PlaneMatches(everything.planes(0), wall_normal, 1.925))
        << everything.planes(0).ShortDebugString();
    bool table_listed = false;
    for (int i = 1; i < everything.planes_size(); ++i) {
      table_listed |= PlaneMatches(everything.planes(i), table_normal, 0.513);
    }
    EXPECT_TRUE(table_listed) << everything.ShortDebugString();
    // In front of the wall (z < 1.5 m) the table is the dominant plane, and it is where the
    // frame's points are: more than half of them lie within 2 cm of it.
    const auto front = FindPlanesBelow(1.5);
    ASSERT_GE(front.planes_size(), 1);
    const v1::Plane& table = front.planes(0);
    EXPECT_TRUE(PlaneMatches(table, table_normal, 0.513)) << table.ShortDebugString();
    EXPECT_GT(table.support_voxels(), 300u) << table.ShortDebugString();
    const Eigen::Vector3d n(table.normal().x(), table.normal().y(), table.normal().z());
    std::size_t on_plane = 0;
    for (const auto& p : points) on_plane += std::abs(n.dot(p) - table.d_m()) < 0.02;
    EXPECT_GT(double(on_plane) / points.size(), 0.5) << table.ShortDebugString();
  }
};

TEST_F(E2ePcdTest, TableIsOccupiedFreeInFrontAndTheDominantPlane) {
  std::string recording;
  std::vector<Eigen::Vector3d> points;
  ASSERT_NO_FATAL_FAILURE(ImportTheFrame(&recording, &points));
  ASSERT_NO_FATAL_FAILURE(ReplayIntoFusiond(recording, points.size()));
  ASSERT_NO_FATAL_FAILURE(ExpectOccupiedAtThePointsFreeHalfWay(points));
  ASSERT_NO_FATAL_FAILURE(ExpectTheTableCentreInABox(points[points.size() / 2]));
  ASSERT_NO_FATAL_FAILURE(ExpectTheTableIsTheDominantPlane(points));
  EXPECT_EQ(fusiond_->Stop(SIGTERM, 10000ms), 0);
}

}  // namespace
