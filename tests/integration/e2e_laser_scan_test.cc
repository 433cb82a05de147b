// End to end with a real 3D laser scan: OctoMap's sample scan (88,206 points in the scanner
// frame: x forward, y left, z up; 180 degrees sideways, -7..+32 degrees up, 0.47..29 m)
// re-expressed in the optical-frame convention, imported with fusion-import scan and a --pose
// that turns the optical frame back into the scanner's, replayed into a fusiond process with a
// 184 x 66 degree sensor of 0.5 degree beams, and queried over gRPC: voxels at the points are
// occupied, half-way to them free.
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
const std::string kScan =
    std::string(FUSION_SHARED_DATA_DIR) + "/octomap_laser_scan/scan.dat.bz2";

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

class E2eLaserScanTest : public E2eService {
 protected:
  void SetUp() override {
    if (!fs::exists(kScan)) {
      GTEST_SKIP() << "OctoMap laser scan missing: " << kScan
                   << " (see ../shared/data/README.md: octomap_laser_scan)";
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
  return static_cast<std::size_t>(std::count_if(
      results.begin(), results.end(), [&](const auto& r) { return r.state() == state; }));
}

TEST_F(E2eLaserScanTest, PointsAreOccupiedAndRaysFree) {
  const auto scan = ReadScan(kScan);
  ASSERT_EQ(scan.size(), 88206u) << "bzip2 -dc " << kScan;

  // The scanner's axes, from the data: x forward (azimuth atan2(y, x) spans -91..+91 deg, x
  // from -0.08 to 27 m), y left, z up (elevation -7..+32 deg, the ground at z ~ -0.1 m).
  // The optical frame (x right, y down, z forward) in the scanner frame: x_o = -y_s,
  // y_o = -z_s, z_o = x_s. With the scanner at (1, 2, 0.5) in the world (axes as the
  // scanner's), the pose of the optical frame is that rotation: q = (-0.5, 0.5, -0.5, 0.5).
  Eigen::Matrix3d R;
  R.col(0) = Eigen::Vector3d(0, -1, 0);
  R.col(1) = Eigen::Vector3d(0, 0, -1);
  R.col(2) = Eigen::Vector3d(1, 0, 0);
  const Eigen::Vector3d t(1.0, 2.0, 0.5);
  const Eigen::Quaterniond q(R);
  ASSERT_NEAR(q.x(), -0.5, 1e-12);
  const std::string text = dir_ + "/scan_optical.txt";
  {
    std::ofstream out(text);
    out.precision(9);
    for (const auto& p : scan) {
      const Eigen::Vector3d o = R.transpose() * p;
      out << o.x() << ' ' << o.y() << ' ' << o.z() << '\n';
    }
  }
  std::ostringstream pose;
  pose.precision(17);
  pose << t.x() << ',' << t.y() << ',' << t.z() << ',' << q.x() << ',' << q.y() << ',' << q.z()
       << ',' << q.w();
  const std::string recording = dir_ + "/scan.frec";
  std::string out;
  ASSERT_EQ(RunTool({"fusion-import", "scan", text, "--pose", pose.str(), "--sensor-id",
                     "scanner", "-o", recording},
                    &out),
            0)
      << out;
  const auto clouds = ReadRecording(recording);
  ASSERT_EQ(clouds.size(), 1u);
  const auto world = WorldPoints(clouds[0]);
  ASSERT_EQ(world.size(), scan.size());
  // The recording's pose puts every point back where the scanner saw it (+ t).
  for (std::size_t i = 0; i < scan.size(); i += 1000) {
    ASSERT_LT((world[i] - (scan[i] + t)).norm(), 1e-4) << i;
  }

  // fusiond: one 184 x 66 degree sensor, 0.5 degree beams, 0.3..30 m, 3 cm noise; 0.15 m map.
  std::ostringstream config;
  config << "log_level: \"warn\"\n"
         << "sensors { id: \"scanner\" model: \"paper3d\" r_min_m: 0.3 r_max_m: 30.0\n"
         << "  fov_h_deg: 184 fov_v_deg: 66 cols: 368 rows: 132 epsilon: 0.02\n"
         << "  q_mu { a2: 0 a1: 1 a0: 0 } q_sigma { a2: 0 a1: 0 a0: 0.03 } }\n"
         << "map { resolution_m: 0.15 render_interval_ms: 100 beam_cell_size_m: 0.02 }\n"
         << "ingest { reliability: \"reliable\" }\n";
  ASSERT_NO_FATAL_FAILURE(StartFusiond(config.str()));
  const auto start = std::chrono::steady_clock::now();
  ASSERT_EQ(RunTool({"fusion-replay", recording, "--domain", std::to_string(domain_), "--fast",
                     "--reliable", "--quiet"},
                    &out),
            0)
      << out;
  ASSERT_TRUE(WaitIntegrated("scanner", 1, 60s));
  std::printf("integrated and rendered in %.1f s\n",
              std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
  const auto counters = Counters("scanner");
  EXPECT_EQ(counters.points_updated(), scan.size()) << counters.ShortDebugString();
  EXPECT_EQ(counters.points_rejected(), 0u) << "the fan lies in the field of view";

  // Occupied at the points (a sample of 1 in 10), free half-way from the scanner to them.
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
  EXPECT_GE(occupied, 0.8) << sample.size() << " points";
  EXPECT_GE(free, 0.8) << half_way.size() << " half-way points";
  // Behind the scanner (x < -0.5 in the scanner frame) nothing was seen.
  const auto behind = Query({t + Eigen::Vector3d(-2, 0, 0.5), t + Eigen::Vector3d(-5, 3, 1)});
  EXPECT_EQ(CountState(behind, v1::VOXEL_STATE_UNKNOWN), 2u);

  EXPECT_EQ(fusiond_->Stop(SIGTERM, 10000ms), 0);
}

}  // namespace
