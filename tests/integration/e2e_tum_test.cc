// End to end with a real depth camera: TUM RGB-D fr2/pioneer_slam2 (10 Kinect frames with
// ground-truth poses) imported with fusion-import tum, replayed with fusion-replay --fast
// --reliable into a fusiond process (private DDS domain, 127.0.0.1:0) configured with an
// explicit Kinect sensor, and queried over gRPC: the hall's floor is found as a horizontal
// plane at the height the data shows.
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <csignal>
#include <chrono>
#include <cmath>
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
const std::string kData = std::string(FUSION_SHARED_DATA_DIR) + "/tum_fr2_pioneer_slam2";
constexpr double kPi = 3.14159265358979323846;
constexpr int kStride = 4;  // 640 x 480 -> 160 x 120
constexpr int kFrames = 10;

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

class E2eTumTest : public E2eService {
 protected:
  void SetUp() override {
    if (!fs::exists(kData + "/groundtruth.txt")) {
      GTEST_SKIP() << "TUM data missing: " << kData
                   << " (see ../shared/data/README.md: tum_fr2_pioneer_slam2)";
    }
    E2eService::SetUp();
  }
};

TEST_F(E2eTumTest, FloorOfTheHallIsFoundAtItsHeight) {
  const auto t0 = std::chrono::steady_clock::now();
  const auto mark = [&](const char* what) {
    std::printf("%6.2f s %s\n", std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(), what);
  };
  // 1. Import every 4th pixel of the 10 frames.
  const std::string recording = dir_ + "/tum.frec";
  std::string out;
  ASSERT_EQ(RunTool({"fusion-import", "tum", kData, "--stride", std::to_string(kStride),
                     "--sensor-id", "kinect", "-o", recording},
                    &out),
            0)
      << out;
  const auto clouds = ReadRecording(recording);
  ASSERT_EQ(clouds.size(), static_cast<std::size_t>(kFrames));
  ASSERT_EQ(clouds[0].width(), 640u / kStride);
  ASSERT_EQ(clouds[0].height(), 480u / kStride);

  // What the data says about the floor: the points below the camera (world z < 0.3) are
  // floor, not flat in this sequence (it rises ~1.6 degrees towards the far side of the hall:
  // ~0.02 m at 1 m from the camera, ~0.17 m at 4 m). A trimmed least-squares plane
  // z = a x + b y + c of them is the reference.
  std::vector<Eigen::Vector3d> low;
  for (const auto& cloud : clouds) {
    for (const auto& p : WorldPoints(cloud)) {
      if (p.z() < 0.3) low.push_back(p);
    }
  }
  ASSERT_GT(low.size(), 10000u) << "the frames should see plenty of floor";
  Eigen::Vector3d abc(0, 0, 0);
  Eigen::Vector3d centroid(0, 0, 0);
  for (int iteration = 0; iteration < 4; ++iteration) {
    Eigen::Matrix3d A = Eigen::Matrix3d::Zero();
    Eigen::Vector3d b = Eigen::Vector3d::Zero();
    centroid.setZero();
    int n = 0;
    for (const auto& p : low) {
      if (iteration > 0 && std::abs(p.z() - abc.dot(Eigen::Vector3d(p.x(), p.y(), 1))) > 0.05) {
        continue;
      }
      const Eigen::Vector3d row(p.x(), p.y(), 1.0);
      A += row * row.transpose();
      b += row * p.z();
      centroid += p;
      ++n;
    }
    abc = A.ldlt().solve(b);
    centroid /= n;
  }
  const auto floor_at = [&](double x, double y) { return abc.dot(Eigen::Vector3d(x, y, 1)); };
  const Eigen::Vector3d floor_normal = Eigen::Vector3d(-abc.x(), -abc.y(), 1).normalized();
  const auto& cam = clouds[0].t_world_sensor();
  // README: the floor is close to z = 0 and the camera about 0.59 m above it.
  ASSERT_NEAR(floor_at(cam.tx(), cam.ty()), 0.0, 0.05);
  EXPECT_NEAR(cam.tz() - floor_at(cam.tx(), cam.ty()), 0.59, 0.05);
  ASSERT_LT(std::acos(floor_normal.z()) * 180.0 / kPi, 3.0);

  // 2. fusiond with an explicit Kinect: the FOV covers every pixel of the image (principal
  // point off centre: 2 atan(max(cx, 639 - cx) / fx)), one beam per decimated pixel,
  // sigma(r) = 0.0012 + 0.0019 (r - 0.4)^2 m.
  const double fov_h = 2.0 * std::atan(325.1 / 520.9) * 180.0 / kPi + 0.5;  // ~64.4 deg
  const double fov_v = 2.0 * std::atan(249.7 / 521.0) * 180.0 / kPi + 0.5;  // ~51.1 deg
  const double s2 = 0.0019, s1 = -2.0 * 0.0019 * 0.4, s0 = 0.0012 + 0.0019 * 0.16;
  std::ostringstream config;
  config << "log_level: \"warn\"\n"
         << "sensors { id: \"kinect\" model: \"paper3d\" r_min_m: 0.5 r_max_m: 7.0\n"
         << "  fov_h_deg: " << fov_h << " fov_v_deg: " << fov_v << "\n"
         << "  cols: " << 640 / kStride << " rows: " << 480 / kStride << " epsilon: 0.02\n"
         << "  q_mu { a2: 0 a1: 1 a0: 0 }\n"
         << "  q_sigma { a2: " << s2 << " a1: " << s1 << " a0: " << s0 << " }\n"
         << "  queue_depth: 20 }\n"
         << "map { resolution_m: 0.05 render_interval_ms: 100 beam_cell_size_m: 0.01 }\n"
         << "ingest { reliability: \"reliable\" }\n";
  mark("imported");
  ASSERT_NO_FATAL_FAILURE(StartFusiond(config.str()));
  mark("started");

  // 3. Replay everything, reliably, as fast as possible.
  ASSERT_EQ(RunTool({"fusion-replay", recording, "--domain", std::to_string(domain_), "--fast",
                     "--reliable", "--wait-readers", "1", "--quiet"},
                    &out),
            0)
      << out;
  EXPECT_NE(out.find("published 10 clouds"), std::string::npos) << out;
  mark("replayed");
  ASSERT_TRUE(WaitIntegrated("kinect", kFrames, 30s))
      << "integrated " << Counters("kinect").integrated() << " of " << kFrames;
  const auto counters = Counters("kinect");
  EXPECT_EQ(counters.received(), static_cast<std::uint64_t>(kFrames));
  EXPECT_EQ(counters.dropped(), 0u);
  EXPECT_EQ(counters.rejected(), 0u);
  EXPECT_EQ(counters.last_sequence_number(), clouds.back().sequence_number());
  // Most decimated pixels carry a depth inside 0.5..7 m and are used.
  EXPECT_GT(counters.points_updated(), 100000u);

  mark("integrated");
  // 4. The floor: a near-horizontal plane at the floor's height.
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + 20s);
  v1::FindPlanesRequest request;
  request.set_max_planes(8);
  v1::FindPlanesResponse planes;
  const auto status = stub_->FindPlanes(&context, request, &planes);
  ASSERT_TRUE(status.ok()) << status.error_message();
  ASSERT_GT(planes.planes_size(), 0);
  mark("planes");
  // The floor: within 5 degrees of horizontal, the largest such plane within 0.3 m of the
  // data's floor at the floor points' centroid.
  const auto height_at = [](const v1::Plane& p, double x, double y) {
    return (p.d_m() - p.normal().x() * x - p.normal().y() * y) / p.normal().z();
  };
  const v1::Plane* floor = nullptr;
  std::string listing;
  for (const auto& p : planes.planes()) {
    listing += p.ShortDebugString() + "\n";
    if (std::abs(p.normal().z()) < std::cos(5.0 * kPi / 180.0)) continue;
    if (std::abs(height_at(p, centroid.x(), centroid.y()) - centroid.z()) > 0.3) continue;
    if (floor == nullptr || p.support_voxels() > floor->support_voxels()) floor = &p;
  }
  ASSERT_NE(floor, nullptr) << "no horizontal plane near the floor (" << centroid.transpose()
                            << ") among:\n"
                            << listing;
  // Where the floor points are, at the data's height (Hough bins: 2 degrees, 5 cm).
  EXPECT_NEAR(height_at(*floor, centroid.x(), centroid.y()), centroid.z(), 0.05) << listing;
  // Under the camera: world z ~ 0.
  EXPECT_NEAR(height_at(*floor, cam.tx(), cam.ty()), floor_at(cam.tx(), cam.ty()), 0.08)
      << listing;
  const Eigen::Vector3d n(floor->normal().x(), floor->normal().y(), floor->normal().z());
  EXPECT_LT(std::acos(std::abs(n.dot(floor_normal))) * 180.0 / kPi, 3.0) << listing;
  EXPECT_GT(floor->support_voxels(), 1000u) << listing;
  EXPECT_LT(floor->rms_m(), 0.05) << listing;
  // It is the floor around the robot: its extent reaches the camera's x, y.
  EXPECT_LT(floor->extent_min().x(), cam.tx() + 0.5) << listing;
  EXPECT_GT(floor->extent_max().x(), cam.tx() - 0.5) << listing;

  // Free space between the camera and the floor ahead: the point 0.3 m above the floor,
  // 2 m in front of the first pose, is free.
  const Eigen::Isometry3d T0 = Pose(cam);
  Eigen::Vector3d ahead = T0.linear().col(2);
  ahead.z() = 0;
  ahead.normalize();
  const Eigen::Vector3d base = T0.translation() + 2.0 * ahead;
  v1::QueryPointsRequest query;
  for (double z : {floor_at(base.x(), base.y()) + 0.3, floor_at(base.x(), base.y())}) {
    auto* q = query.add_points();
    q->set_x(base.x());
    q->set_y(base.y());
    q->set_z(z);
  }
  grpc::ClientContext query_context;
  query_context.set_deadline(std::chrono::system_clock::now() + 5s);
  v1::QueryPointsResponse occupancy;
  ASSERT_TRUE(stub_->QueryPoints(&query_context, query, &occupancy).ok());
  ASSERT_EQ(occupancy.results_size(), 2);
  EXPECT_EQ(occupancy.results(0).state(), v1::VOXEL_STATE_FREE)
      << occupancy.results(0).ShortDebugString();

  EXPECT_EQ(fusiond_->Stop(SIGTERM, 10000ms), 0);
}

}  // namespace
