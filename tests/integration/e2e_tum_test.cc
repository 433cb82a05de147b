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
using fusion::testing::Pose;
using fusion::testing::ReadRecording;
using fusion::testing::RunTool;
using fusion::testing::Subprocess;
using fusion::testing::WorldPoints;
using namespace std::chrono_literals;
namespace v1 = fusion::v1;
namespace fs = std::filesystem;

const std::string kData = std::string(FUSION_SHARED_DATA_DIR) + "/tum_fr2_pioneer_slam2";
constexpr double kPi = 3.14159265358979323846;
constexpr int kStride = 4;  // 640 x 480 -> 160 x 120
constexpr int kFrames = 10;

// The data's floor: z = a x + b y + c (abc), fitted to the floor points, and their centroid.
struct FloorFit {
  Eigen::Vector3d abc = Eigen::Vector3d::Zero();
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  [[nodiscard]] double At(double x, double y) const { return abc.dot(Eigen::Vector3d(x, y, 1)); }
  [[nodiscard]] Eigen::Vector3d Normal() const {
    return Eigen::Vector3d(-abc.x(), -abc.y(), 1).normalized();
  }
};

// A trimmed least-squares plane of the points: 4 iterations, each after the first without the
// points more than 5 cm off the previous plane.
FloorFit FitFloor(const std::vector<Eigen::Vector3d>& low) {
  FloorFit fit;
  for (int iteration = 0; iteration < 4; ++iteration) {
    Eigen::Matrix3d A = Eigen::Matrix3d::Zero();
    Eigen::Vector3d b = Eigen::Vector3d::Zero();
    fit.centroid.setZero();
    int n = 0;
    for (const auto& p : low) {
      if (iteration > 0 && std::abs(p.z() - fit.At(p.x(), p.y())) > 0.05) continue;
      const Eigen::Vector3d row(p.x(), p.y(), 1.0);
      A += row * row.transpose();
      b += row * p.z();
      fit.centroid += p;
      ++n;
    }
    fit.abc = A.ldlt().solve(b);
    fit.centroid /= n;
  }
  return fit;
}

// A found plane's height z at (x, y).
double HeightAt(const v1::Plane& p, double x, double y) {
  return (p.d_m() - p.normal().x() * x - p.normal().y() * y) / p.normal().z();
}

// 2. fusiond with an explicit Kinect: the FOV covers every pixel of the image (principal
// point off centre: 2 atan(max(cx, 639 - cx) / fx)), one beam per decimated pixel,
// sigma(r) = 0.0012 + 0.0019 (r - 0.4)^2 m.
std::string KinectConfig() {
  const double fov_h = 2.0 * std::atan(325.1 / 520.9) * 180.0 / kPi + 0.5;  // ~64.4 deg
  const double fov_v = 2.0 * std::atan(249.7 / 521.0) * 180.0 / kPi + 0.5;  // ~51.1 deg
  const double s2 = 0.0019, s1 = -2.0 * 0.0019 * 0.4, s0 = 0.0012 + 0.0019 * 0.16;
  std::ostringstream config;
  config << "log_level: \"warn\"\n"
         << "sensors { id: \"kinect\" model: \"paper3d\" r_min_m: 0.5 r_max_m: 6.0\n"
         << "  fov_h_deg: " << fov_h << " fov_v_deg: " << fov_v << "\n"
         << "  cols: " << 640 / kStride << " rows: " << 480 / kStride << " epsilon: 0.02\n"
         << "  q_mu { a2: 0 a1: 1 a0: 0 }\n"
         << "  q_sigma { a2: " << s2 << " a1: " << s1 << " a0: " << s0 << " }\n"
         << "  queue_depth: 20 }\n"
         << "map { resolution_m: 0.05 render_interval_ms: 100 beam_cell_size_m: 0.02 }\n"
         << "ingest { reliability: \"reliable\" }\n";
  return config.str();
}

class E2eTumTest : public E2eService {
 protected:
  void SetUp() override {
    if (!fs::exists(kData + "/groundtruth.txt")) {
      GTEST_SKIP() << "TUM data missing: " << kData
                   << " (see ../shared/data/README.md: tum_fr2_pioneer_slam2)";
    }
    E2eService::SetUp();
  }

  // The steps of FloorOfTheHallIsFoundAtItsHeight; the test calls each in
  // ASSERT_NO_FATAL_FAILURE, so that a failed ASSERT in a step ends the test as it did when
  // the steps were inline.

  // Prints the seconds since the test started and what was done by then.
  void Mark(const char* what) const {
    std::printf("%6.2f s %s\n",
                std::chrono::duration<double>(std::chrono::steady_clock::now() - t0_).count(),
                what);
  }

  // 1. Import every 4th pixel of the 10 frames into `recording`.
  void ImportTheFrames(const std::string& recording, std::vector<v1::RecordedCloud>* clouds) {
    std::string out;
    ASSERT_EQ(RunTool({"fusion-import", "tum", kData, "--stride", std::to_string(kStride),
                       "--sensor-id", "kinect", "-o", recording},
                      &out),
              0)
        << out;
    *clouds = ReadRecording(recording);
    ASSERT_EQ(clouds->size(), static_cast<std::size_t>(kFrames));
    ASSERT_EQ((*clouds)[0].width(), 640u / kStride);
    ASSERT_EQ((*clouds)[0].height(), 480u / kStride);
  }

  // What the data says about the floor: the points below the camera (world z < 0.3) are
  // floor, not flat in this sequence (it rises ~1.6 degrees towards the far side of the hall:
  // ~0.02 m at 1 m from the camera, ~0.17 m at 4 m). A trimmed least-squares plane
  // z = a x + b y + c of them is the reference.
  void FitTheDatasFloor(const std::vector<v1::RecordedCloud>& clouds, FloorFit* floor) {
    std::vector<Eigen::Vector3d> low;
    for (const auto& cloud : clouds) {
      for (const auto& p : WorldPoints(cloud)) {
        if (p.z() < 0.3) low.push_back(p);
      }
    }
    ASSERT_GT(low.size(), 10000u) << "the frames should see plenty of floor";
    *floor = FitFloor(low);
    const auto& cam = clouds[0].t_world_sensor();
    // README: the floor is close to z = 0 and the camera about 0.59 m above it.
    ASSERT_NEAR(floor->At(cam.tx(), cam.ty()), 0.0, 0.05);
    EXPECT_NEAR(cam.tz() - floor->At(cam.tx(), cam.ty()), 0.59, 0.05);
    ASSERT_LT(std::acos(floor->Normal().z()) * 180.0 / kPi, 3.0);
  }

  // 3. Replay everything, reliably, as fast as possible; every cloud reaches the map.
  void ReplayEveryCloud(const std::string& recording,
                        const std::vector<v1::RecordedCloud>& clouds) {
    std::string out;
    ASSERT_EQ(RunTool({"fusion-replay", recording, "--domain", std::to_string(domain_), "--fast",
                       "--reliable", "--wait-readers", "1", "--quiet"},
                      &out),
              0)
        << out;
    EXPECT_NE(out.find("published 10 clouds"), std::string::npos) << out;
    Mark("replayed");
    ASSERT_TRUE(WaitInMap(kFrames, 30s))
        << "integrated " << Counters("kinect").integrated() << " of " << kFrames;
    const auto counters = Counters("kinect");
    EXPECT_EQ(counters.received(), static_cast<std::uint64_t>(kFrames));
    EXPECT_EQ(counters.dropped(), 0u);
    EXPECT_EQ(counters.rejected(), 0u);
    EXPECT_EQ(counters.last_sequence_number(), clouds.back().sequence_number());
    // Most decimated pixels carry a depth inside 0.5..7 m and are used.
    EXPECT_GT(counters.points_updated(), 100000u);
  }

  // 4. The floor: a near-horizontal plane at the floor's height. `cam`: the first pose.
  void ExpectTheFloorPlane(const FloorFit& data_floor, const v1::RecordedPose& cam) {
    grpc::ClientContext context;
    // An expensive call on the low-priority pool: generous for sanitizer builds.
    context.set_deadline(std::chrono::system_clock::now() + 120s);
    v1::FindPlanesRequest request;
    request.set_max_planes(8);
    v1::FindPlanesResponse planes;
    const auto status = stub_->FindPlanes(&context, request, &planes);
    ASSERT_TRUE(status.ok()) << status.error_message();
    ASSERT_GT(planes.planes_size(), 0);
    Mark("planes");
    // The floor: within 5 degrees of horizontal, the largest such plane within 0.3 m of the
    // data's floor at the floor points' centroid.
    const Eigen::Vector3d& centroid = data_floor.centroid;
    const v1::Plane* floor = nullptr;
    std::string listing;
    for (const auto& p : planes.planes()) {
      listing += p.ShortDebugString() + "\n";
      if (std::abs(p.normal().z()) < std::cos(5.0 * kPi / 180.0)) continue;
      if (std::abs(HeightAt(p, centroid.x(), centroid.y()) - centroid.z()) > 0.3) continue;
      if (floor == nullptr || p.support_voxels() > floor->support_voxels()) floor = &p;
    }
    ASSERT_NE(floor, nullptr) << "no horizontal plane near the floor (" << centroid.transpose()
                              << ") among:\n"
                              << listing;
    // Where the floor points are, at the data's height (Hough bins: 2 degrees, 5 cm).
    EXPECT_NEAR(HeightAt(*floor, centroid.x(), centroid.y()), centroid.z(), 0.05) << listing;
    // Under the camera: world z ~ 0.
    EXPECT_NEAR(HeightAt(*floor, cam.tx(), cam.ty()), data_floor.At(cam.tx(), cam.ty()), 0.08)
        << listing;
    const Eigen::Vector3d n(floor->normal().x(), floor->normal().y(), floor->normal().z());
    EXPECT_LT(std::acos(std::abs(n.dot(data_floor.Normal()))) * 180.0 / kPi, 3.0) << listing;
    EXPECT_GT(floor->support_voxels(), 1000u) << listing;
    EXPECT_LT(floor->rms_m(), 0.05) << listing;
    // It is the floor around the robot: its extent reaches the camera's x, y.
    EXPECT_LT(floor->extent_min().x(), cam.tx() + 0.5) << listing;
    EXPECT_GT(floor->extent_max().x(), cam.tx() - 0.5) << listing;
  }

  // Free space between the camera and the floor ahead: the point 0.3 m above the floor,
  // 2 m in front of the first pose `cam`, is free.
  void ExpectFreeAboveTheFloorAhead(const FloorFit& data_floor, const v1::RecordedPose& cam) {
    const Eigen::Isometry3d T0 = Pose(cam);
    Eigen::Vector3d ahead = T0.linear().col(2);
    ahead.z() = 0;
    ahead.normalize();
    const Eigen::Vector3d base = T0.translation() + 2.0 * ahead;
    v1::QueryPointsRequest query;
    for (double z : {data_floor.At(base.x(), base.y()) + 0.3, data_floor.At(base.x(), base.y())}) {
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
  }

  std::chrono::steady_clock::time_point t0_;  // the test's start, for Mark
};

TEST_F(E2eTumTest, FloorOfTheHallIsFoundAtItsHeight) {
  t0_ = std::chrono::steady_clock::now();
  const std::string recording = dir_ + "/tum.frec";
  std::vector<v1::RecordedCloud> clouds;
  ASSERT_NO_FATAL_FAILURE(ImportTheFrames(recording, &clouds));
  FloorFit floor;
  ASSERT_NO_FATAL_FAILURE(FitTheDatasFloor(clouds, &floor));
  Mark("imported");
  ASSERT_NO_FATAL_FAILURE(StartFusiond(KinectConfig()));
  Mark("started");
  ASSERT_NO_FATAL_FAILURE(ReplayEveryCloud(recording, clouds));
  Mark("integrated");
  const auto& cam = clouds[0].t_world_sensor();
  ASSERT_NO_FATAL_FAILURE(ExpectTheFloorPlane(floor, cam));
  ASSERT_NO_FATAL_FAILURE(ExpectFreeAboveTheFloorAhead(floor, cam));
  EXPECT_EQ(fusiond_->Stop(SIGTERM, 10000ms), 0);
}

}  // namespace
