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
#include <cstring>
#include <filesystem>
#include <fstream>
#include <memory>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "../support/subprocess.h"
#include "fusion/v1/map_service.grpc.pb.h"
#include "fusion/v1/recording.pb.h"

namespace {

using fusion::testing::Subprocess;
using namespace std::chrono_literals;
namespace v1 = fusion::v1;
namespace fs = std::filesystem;

const std::string kBuild = FUSION_BINARY_DIR;
const std::string kTools = kBuild + "/clients/";
const std::string kPcd =
    std::string(FUSION_SHARED_DATA_DIR) + "/pcl_stereo/table_scene_mug_stereo_textured.pcd";
constexpr double kPi = 3.14159265358979323846;

// Runs a tool to completion; returns its exit code (-1: did not finish) and stdout.
int RunTool(std::vector<std::string> argv, std::string* out = nullptr,
            std::chrono::seconds timeout = 60s) {
  argv[0] = kTools + argv[0];
  Subprocess process(argv);
  if (!process.started()) return -1;
  process.WaitForOutput("(?!)", timeout);  // drains stdout until the child exits
  const int code = process.Wait(5000ms);
  if (out) *out = process.output();
  return code;
}

// The clouds of a .frec file (docs/recording-format.md), read frame by frame.
std::vector<v1::RecordedCloud> ReadRecording(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::vector<v1::RecordedCloud> clouds;
  for (;;) {
    std::uint32_t head[2];
    if (!in.read(reinterpret_cast<char*>(head), sizeof head)) break;
    std::string payload(head[0], '\0');
    if (!in.read(payload.data(), head[0])) break;
    v1::RecordingFrame frame;
    if (!frame.ParseFromString(payload)) break;
    if (frame.has_cloud()) clouds.push_back(frame.cloud());
    if (frame.has_index()) break;
  }
  return clouds;
}

Eigen::Isometry3d Pose(const v1::RecordedPose& p) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = Eigen::Quaterniond(p.qw(), p.qx(), p.qy(), p.qz()).normalized().toRotationMatrix();
  T.translation() = Eigen::Vector3d(p.tx(), p.ty(), p.tz());
  return T;
}

// The finite points of a cloud in the world frame.
std::vector<Eigen::Vector3d> WorldPoints(const v1::RecordedCloud& cloud) {
  std::vector<float> xyz(cloud.xyz_f32le().size() / sizeof(float));
  std::memcpy(xyz.data(), cloud.xyz_f32le().data(), xyz.size() * sizeof(float));
  const Eigen::Isometry3d T = Pose(cloud.t_world_sensor());
  std::vector<Eigen::Vector3d> points;
  for (std::size_t i = 0; i + 2 < xyz.size(); i += 3) {
    const Eigen::Vector3d p(xyz[i], xyz[i + 1], xyz[i + 2]);
    if (p.allFinite()) points.push_back(T * p);
  }
  return points;
}

// A fusiond process with its own temporary folder and DDS domain, and gRPC stubs to it.
class E2eService : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = ::testing::TempDir() + "e2e_" + std::to_string(getpid()) + "_" +
           ::testing::UnitTest::GetInstance()->current_test_info()->name();
    fs::remove_all(dir_);
    fs::create_directories(dir_);
    domain_ = fusion::testing::PrivateDomainId();
  }
  void TearDown() override {
    if (!dir_.empty()) fs::remove_all(dir_);
  }

  // Starts fusiond with `config` (written to the temporary folder) on 127.0.0.1:0 in the
  // test's DDS domain, plus `extra` flags.
  void StartFusiond(const std::string& config, std::vector<std::string> extra = {}) {
    const std::string path = dir_ + "/fusiond.pbtxt";
    std::ofstream(path) << config;
    StartFusiondWithFile(path, std::move(extra));
  }
  void StartFusiondWithFile(const std::string& path, std::vector<std::string> extra = {}) {
    std::vector<std::string> argv = {kBuild + "/service/fusiond", "--config", path, "--listen",
                                     "127.0.0.1:0", "--dds-domain", std::to_string(domain_)};
    argv.insert(argv.end(), extra.begin(), extra.end());
    fusiond_ = std::make_unique<Subprocess>(argv);
    ASSERT_TRUE(fusiond_->started());
    const auto port = fusiond_->WaitForOutput(R"(fusiond listening on 127\.0\.0\.1:(\d+))", 20s);
    ASSERT_TRUE(port) << "no 'listening' line: " << fusiond_->output();
    address_ = "127.0.0.1:" + *port;
    stub_ = v1::FusionMap::NewStub(grpc::CreateChannel(address_, grpc::InsecureChannelCredentials()));
  }

  v1::SensorCounters Counters(const std::string& id) {
    grpc::ClientContext context;
    context.set_deadline(std::chrono::system_clock::now() + 5s);
    v1::ListSensorsResponse reply;
    const auto status = stub_->ListSensors(&context, v1::ListSensorsRequest(), &reply);
    EXPECT_TRUE(status.ok()) << status.error_message();
    for (const auto& s : reply.sensors()) {
      if (s.id() == id) return s.counters();
    }
    ADD_FAILURE() << "sensor " << id << " not listed";
    return {};
  }

  v1::Stats Stats() {
    grpc::ClientContext context;
    context.set_deadline(std::chrono::system_clock::now() + 5s);
    v1::Stats stats;
    EXPECT_TRUE(stub_->GetStats(&context, v1::GetStatsRequest(), &stats).ok());
    return stats;
  }

  // Waits until `frames` clouds of sensor `id` are integrated and rendered.
  bool WaitIntegrated(const std::string& id, std::uint64_t frames, std::chrono::seconds timeout,
                      std::chrono::milliseconds quiet = 500ms) {
    const auto end = std::chrono::steady_clock::now() + timeout;
    while (Counters(id).integrated() < frames) {
      if (std::chrono::steady_clock::now() > end) return false;
      std::this_thread::sleep_for(50ms);
    }
    // The worker renders pending changes every render_interval_ms (100 ms here): once no
    // render happened for `quiet`, the last cloud is in the published map.
    auto renders = Stats().renders();
    for (;;) {
      std::this_thread::sleep_for(quiet);
      const auto now = Stats().renders();
      if (now == renders || std::chrono::steady_clock::now() > end) break;
      renders = now;
    }
    return true;
  }

  std::string dir_;
  unsigned domain_ = 0;
  std::unique_ptr<Subprocess> fusiond_;
  std::unique_ptr<v1::FusionMap::Stub> stub_;
  std::string address_;
};

class E2ePcdTest : public E2eService {
 protected:
  void SetUp() override {
    if (!fs::exists(kPcd)) {
      GTEST_SKIP() << "PCL stereo frame missing: " << kPcd
                   << " (see ../shared/data/README.md: pcl_stereo)";
    }
    E2eService::SetUp();
  }

  std::vector<v1::PointOccupancy> Query(const std::vector<Eigen::Vector3d>& points) {
    v1::QueryPointsRequest request;
    for (const auto& p : points) {
      auto* q = request.add_points();
      q->set_x(p.x());
      q->set_y(p.y());
      q->set_z(p.z());
    }
    grpc::ClientContext context;
    context.set_deadline(std::chrono::system_clock::now() + 10s);
    v1::QueryPointsResponse reply;
    const auto status = stub_->QueryPoints(&context, request, &reply);
    EXPECT_TRUE(status.ok()) << status.error_message();
    return {reply.results().begin(), reply.results().end()};
  }
};

std::size_t CountState(const std::vector<v1::PointOccupancy>& results, v1::VoxelState state) {
  return static_cast<std::size_t>(std::count_if(
      results.begin(), results.end(), [&](const auto& r) { return r.state() == state; }));
}

TEST_F(E2ePcdTest, TableIsOccupiedFreeInFrontAndTheDominantPlane) {
  // 1. The file's VIEWPOINT (a half turn about x) would put every point behind the camera;
  // the points are in the camera's optical frame already: --ignore-viewpoint keeps them.
  const std::string with_viewpoint = dir_ + "/viewpoint.frec";
  const std::string recording = dir_ + "/table.frec";
  std::string out;
  ASSERT_EQ(RunTool({"fusion-import", "pcd", kPcd, "--sensor-id", "stereo", "-o", with_viewpoint},
                    &out),
            0)
      << out;
  ASSERT_EQ(RunTool({"fusion-import", "pcd", "--ignore-viewpoint", kPcd, "--sensor-id", "stereo",
                     "-o", recording},
                    &out),
            0)
      << out;
  const auto turned = ReadRecording(with_viewpoint);
  const auto clouds = ReadRecording(recording);
  ASSERT_EQ(turned.size(), 1u);
  ASSERT_EQ(clouds.size(), 1u);
  ASSERT_EQ(clouds[0].width(), 640u);
  ASSERT_EQ(clouds[0].height(), 480u);
  const auto behind = WorldPoints(turned[0]);  // world = the VIEWPOINT pose applied back
  const auto points = WorldPoints(clouds[0]);  // identity pose: camera frame = world
  ASSERT_GT(points.size(), 200000u);           // 209,280 of 307,200 pixels have a disparity
  std::size_t in_front = 0, behind_in_sensor = 0;
  {
    std::vector<float> xyz(turned[0].xyz_f32le().size() / sizeof(float));
    std::memcpy(xyz.data(), turned[0].xyz_f32le().data(), xyz.size() * sizeof(float));
    for (std::size_t i = 2; i < xyz.size(); i += 3) behind_in_sensor += xyz[i] < 0;
  }
  for (const auto& p : points) in_front += p.z() > 0;
  EXPECT_EQ(behind_in_sensor, behind.size()) << "with the VIEWPOINT every point is behind";
  EXPECT_EQ(in_front, points.size()) << "without it every point is in front";

  // 2. fusiond with the stereo camera: 640 x 480 pixels of fx ~ 964 px (measured from the
  // points: x/z changes by 1/964 per column) and the principal point near (320, 223): 37 x 30
  // degrees covers every pixel; 160 x 120 beams = 4 x 4 pixels (several samples) per beam.
  // Stereo noise grows with r^2: sigma(r) = 3 mm + 4 mm/m^2 r^2.
  std::ostringstream config;
  config << "log_level: \"warn\"\n"
         << "sensors { id: \"stereo\" model: \"paper3d\" r_min_m: 0.3 r_max_m: 3.0\n"
         << "  fov_h_deg: 37.0 fov_v_deg: 30.0 cols: 160 rows: 120 epsilon: 0.02\n"
         << "  q_mu { a2: 0 a1: 1 a0: 0 } q_sigma { a2: 0.004 a1: 0 a0: 0.003 } }\n"
         << "map { resolution_m: 0.02 render_interval_ms: 100 beam_cell_size_m: 0.005 }\n"
         << "ingest { reliability: \"reliable\" }\n";
  ASSERT_NO_FATAL_FAILURE(StartFusiond(config.str()));
  ASSERT_EQ(RunTool({"fusion-replay", recording, "--domain", std::to_string(domain_), "--fast",
                     "--reliable", "--quiet"},
                    &out),
            0)
      << out;
  ASSERT_TRUE(WaitIntegrated("stereo", 1, 30s));
  const auto counters = Counters("stereo");
  EXPECT_EQ(counters.rejected(), 0u);
  EXPECT_EQ(counters.points_updated(), points.size()) << counters.ShortDebugString();
  EXPECT_EQ(counters.points_missing(), 640u * 480u - points.size());
  EXPECT_EQ(counters.points_rejected(), 0u) << "every pixel lies in the field of view";

  // 3. Occupied where the points are, free half-way between the camera and them.
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
  EXPECT_GE(occupied, 0.8) << sample.size() << " points";
  EXPECT_GE(free, 0.9) << half_way.size() << " points";
  // No point of the sample lies in free space.
  EXPECT_LE(CountState(at_points, v1::VOXEL_STATE_FREE), sample.size() / 50);

  // QueryBox around a patch of the table centre: occupied voxels, and free ones in front.
  {
    const Eigen::Vector3d c = points[points.size() / 2];
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

  // 4. The dominant plane is the table: 59% of the frame's points lie within 1 cm of
  // n = (-0.015, 0.848, 0.529), d = 0.513 m (a RANSAC fit of the data).
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + 20s);
  v1::FindPlanesRequest request;
  request.set_max_planes(4);
  v1::FindPlanesResponse planes;
  const auto status = stub_->FindPlanes(&context, request, &planes);
  ASSERT_TRUE(status.ok()) << status.error_message();
  ASSERT_GT(planes.planes_size(), 0);
  const v1::Plane* table = &planes.planes(0);
  for (const auto& p : planes.planes()) {
    if (p.support_voxels() > table->support_voxels()) table = &p;
  }
  const Eigen::Vector3d n(table->normal().x(), table->normal().y(), table->normal().z());
  const Eigen::Vector3d expected = Eigen::Vector3d(-0.015, 0.848, 0.529).normalized();
  const double sign = n.dot(expected) < 0 ? -1.0 : 1.0;
  EXPECT_LT(std::acos(std::min(1.0, sign * n.dot(expected))) * 180.0 / kPi, 5.0)
      << table->ShortDebugString();
  EXPECT_NEAR(sign * table->d_m(), 0.513, 0.03) << table->ShortDebugString();
  std::size_t on_plane = 0;
  for (const auto& p : points) on_plane += std::abs(n.dot(p) - table->d_m()) < 0.02;
  EXPECT_GT(double(on_plane) / points.size(), 0.5) << table->ShortDebugString();

  EXPECT_EQ(fusiond_->Stop(SIGTERM, 10000ms), 0);
}

}  // namespace
