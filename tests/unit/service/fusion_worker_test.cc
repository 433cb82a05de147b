// FusionWorker: the published map follows the live map, including voxels that lose their
// information (deleted from the published octree, not left behind); a moving sensor's periods
// are committed in order, each cloud counted once (the same map as core's WorldMap fed on one
// thread); a moving sensor's frame is in the map before the next one comes; another sensor's
// clouds are integrated while one sensor's period renders; a renderer that
// falls behind gets clouds merged, never dropped; a cloud of a camera still waiting for its
// CameraInfo is counted as rejected.
#include "fusion/service/fusion_worker.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <thread>
#include <tuple>
#include <vector>

namespace fusion::service {
namespace {

using namespace std::chrono_literals;

constexpr double kResolutionM = 0.05;

// Every beam of the tessellation reads a return at range_m (sensor frame = world frame).
Cloud WallAt(const BeamTessellation& tessellation, double range_m, std::uint64_t seq) {
  Cloud cloud;
  cloud.sensor_id = "s";
  cloud.sequence_number = seq;
  cloud.width = static_cast<std::uint32_t>(tessellation.cols());
  cloud.height = static_cast<std::uint32_t>(tessellation.rows());
  for (std::size_t b = 0; b < tessellation.beam_count(); ++b) {
    const Eigen::Vector3d p = range_m * tessellation.Direction(b);
    cloud.xyz.insert(cloud.xyz.end(), {static_cast<float>(p.x()), static_cast<float>(p.y()),
                                       static_cast<float>(p.z())});
  }
  return cloud;
}

// A sensor driving sideways, 5 cm a frame (beyond the 1 cm tolerance): one period per cloud.
Cloud Driving(const BeamTessellation& tessellation, int k) {
  Cloud cloud = WallAt(tessellation, 2.0 + 0.1 * (k % 3), static_cast<std::uint64_t>(k + 1));
  cloud.T_world_published = Eigen::Translation3d(0.05 * k, 0.0, 0.0) * Eigen::Isometry3d::Identity();
  return cloud;
}

class FusionWorkerTest : public ::testing::Test {
 protected:
  void SetUp() override { StartWorker(16, 12, Options()); }
  void TearDown() override {
    if (worker_) worker_->Stop();
  }

  static WorkerOptions Options() {
    WorkerOptions options;
    options.map.resolution_m = kResolutionM;
    options.map.render.resolution_m = kResolutionM;
    options.map.render.max_range_m = 4.0;
    options.render_interval = 10ms;
    options.nice = 0;
    return options;
  }

  void StartWorker(int cols, int rows, const WorkerOptions& options) {
    if (worker_) worker_->Stop();
    sensor_.id = "s";
    sensor_.spec = *SensorPreset("sr3000");
    sensor_.spec.cols = cols;
    sensor_.spec.rows = rows;
    tessellation_ = std::make_unique<BeamTessellation>(sensor_.spec);
    worker_ = std::make_unique<FusionWorker>(options, std::vector<SensorSetup>{sensor_}, &queues_,
                                             &hub_);
    const fusion::Status started = worker_->Start(nullptr);
    ASSERT_TRUE(started.ok()) << started.message();
  }

  // Queues `frames` clouds of a wall at range_m and waits until the map holds them.
  void Feed(double range_m, int frames) {
    for (int i = 0; i < frames; ++i) {
      ASSERT_TRUE(queues_.Push(WallAt(*tessellation_, range_m, ++seq_), &never_));
    }
    const auto end = std::chrono::steady_clock::now() + 20s;
    while (worker_->in_map() < seq_ && std::chrono::steady_clock::now() < end) {
      std::this_thread::sleep_for(5ms);
    }
    ASSERT_EQ(worker_->in_map(), seq_);
  }

  // Core's WorldMap with the sensor added and the first `clouds` clouds of Driving integrated in
  // order on this thread (not rendered, not committed).
  void FeedTheDrive(WorldMap* map, int clouds) const {
    ASSERT_EQ(map->AddSensor("s", sensor_.spec), MapStatus::kOk);
    for (int k = 0; k < clouds; ++k) {
      const Cloud cloud = Driving(*tessellation_, k);
      ASSERT_EQ(map->Integrate("s", cloud.T_world_published, cloud.xyz.data(),
                               cloud.xyz.size() / 3),
                MapStatus::kOk);
    }
  }

  static const octomap::OcTreeNode* On(const octomap::OcTree& tree, double z_m) {
    return tree.search(0.01, 0.01, z_m);
  }

  IngestQueues queues_{{{"s", 64}}};
  SensorSetup sensor_;
  SnapshotHub hub_{SnapshotHub::kDefaultMaxLoggedRegions, kResolutionM};
  std::unique_ptr<BeamTessellation> tessellation_;
  std::unique_ptr<FusionWorker> worker_;
  std::uint64_t seq_ = 0;
  std::atomic<bool> never_{false};
};

TEST_F(FusionWorkerTest, VoxelsThatLoseTheirInformationLeaveThePublishedMap) {
  Feed(2.0, 5);
  {
    const auto snapshot = hub_.Current();
    const octomap::OcTreeNode* wall = On(*snapshot->tree, 2.0);
    ASSERT_NE(wall, nullptr);
    EXPECT_GT(wall->getLogOdds(), 0.0f) << "the wall at 2 m is occupied";
  }
  // The wall moves to 1 m and stays there: the beams' first hits concentrate at 1 m, the rays
  // stop there, and nothing is known any more at 2 m.
  Feed(1.0, 40);
  const auto snapshot = hub_.Current();
  const octomap::OcTree& tree = *snapshot->tree;
  const octomap::OcTreeNode* near = On(tree, 1.0);
  ASSERT_NE(near, nullptr);
  EXPECT_GT(near->getLogOdds(), 0.0f) << "the wall at 1 m is occupied";
  EXPECT_EQ(On(tree, 2.0), nullptr) << "the voxel at 2 m is unknown: no node";
  // The octree stays consistent after the deletions: every inner value is the max of its
  // children, so the root holds the largest leaf value, and no node is at log-odds 0.
  float largest = -1e9f;
  std::size_t leaves = 0;
  for (auto it = tree.begin_leafs(), end = tree.end_leafs(); it != end; ++it) {
    largest = std::max(largest, it->getLogOdds());
    EXPECT_NE(it->getLogOdds(), 0.0f);
    ++leaves;
  }
  ASSERT_GT(leaves, 0u);
  EXPECT_FLOAT_EQ(tree.getRoot()->getLogOdds(), largest);
}

// Every leaf of a tree: key, depth and value, in the tree's order.
std::vector<std::tuple<std::size_t, unsigned, float>> Leaves(const octomap::OcTree& tree) {
  std::vector<std::tuple<std::size_t, unsigned, float>> out;
  for (auto it = tree.begin_leafs(), end = tree.end_leafs(); it != end; ++it) {
    out.emplace_back(octomap::OcTreeKey::KeyHash()(it.getKey()), it.getDepth(), it->getLogOdds());
  }
  return out;
}


TEST_F(FusionWorkerTest, MovingPeriodsAreCommittedInOrderEachCloudOnce) {
  WorkerOptions options = Options();
  options.wait_for_renderer = true;  // reliable ingest: the map exactly as taken
  StartWorker(16, 12, options);
  constexpr int kClouds = 12;
  for (int k = 0; k < kClouds; ++k) {
    ASSERT_TRUE(queues_.Push(Driving(*tessellation_, k), &never_));
  }
  worker_->Stop();
  EXPECT_EQ(worker_->in_map(), static_cast<std::uint64_t>(kClouds));
  EXPECT_EQ(queues_.counters("s")->merged.load(), 0u);
  // Core's WorldMap fed the same clouds in order on one thread: the same map, leaf by leaf.
  WorldMap expected(options.map);
  FeedTheDrive(&expected, kClouds);
  ASSERT_EQ(expected.Commit("s"), MapStatus::kOk);
  const auto published = hub_.Current();
  ASSERT_GT(expected.tree().getNumLeafNodes(), 100u);
  EXPECT_EQ(Leaves(*published->tree), Leaves(expected.tree()));
}

// A moving sensor's frame is rendered when it comes in, not when the next frame seals its
// period or after render_interval; that render is the one the period's commit uses.
TEST_F(FusionWorkerTest, AMovingSensorsFrameIsInTheMapBeforeTheNextOne) {
  WorkerOptions options = Options();
  options.render_interval = 60s;  // an open period with more frames waits a minute
  StartWorker(16, 12, options);
  const auto in_map_within = [&](std::uint64_t clouds, std::chrono::seconds limit) {
    const auto end = std::chrono::steady_clock::now() + limit;
    while (worker_->in_map() < clouds && std::chrono::steady_clock::now() < end) {
      std::this_thread::sleep_for(5ms);
    }
    return worker_->in_map();
  };
  constexpr int kClouds = 3;
  for (int k = 0; k < kClouds; ++k) {
    ASSERT_TRUE(queues_.Push(Driving(*tessellation_, k), &never_));
    EXPECT_EQ(in_map_within(k + 1, 20s), static_cast<std::uint64_t>(k + 1))
        << "cloud " << k << " waits for another";
  }
  EXPECT_EQ(worker_->renders(), static_cast<std::uint64_t>(kClouds)) << "one render a period";
  // The same map as core's WorldMap with the last period rendered but open.
  WorldMap expected(options.map);
  FeedTheDrive(&expected, kClouds);
  ASSERT_EQ(expected.Render("s"), MapStatus::kOk);
  EXPECT_EQ(Leaves(*hub_.Current()->tree), Leaves(expected.tree()));
}

double SumOfAbsLogOdds(const octomap::OcTree& tree) {
  double sum = 0.0;
  for (auto it = tree.begin_leafs(), end = tree.end_leafs(); it != end; ++it) {
    sum += std::abs(it->getLogOdds()) * static_cast<double>(1u << (3 * (16 - it.getDepth())));
  }
  return sum;
}

// map.forget_half_life_s: the renderer lets time pass over the committed history on its own
// clock, and publishes what decayed.
TEST_F(FusionWorkerTest, TheHistoryDecaysWithTheHalfLifeWhileNobodyLooks) {
  WorkerOptions options = Options();
  options.wait_for_renderer = true;
  options.map.forget_half_life_s = 1.0;  // a step a second
  StartWorker(16, 12, options);
  for (int k = 0; k < 6; ++k) ASSERT_TRUE(queues_.Push(Driving(*tessellation_, k), &never_));
  const auto end = std::chrono::steady_clock::now() + 20s;
  while (worker_->in_map() < 6 && std::chrono::steady_clock::now() < end) {
    std::this_thread::sleep_for(5ms);
  }
  ASSERT_EQ(worker_->in_map(), 6u);
  const auto before = hub_.Current();
  const double evidence_before = SumOfAbsLogOdds(*before->tree);
  ASSERT_GT(evidence_before, 0.0);
  std::this_thread::sleep_for(2500ms);
  const auto after = hub_.Current();
  EXPECT_GT(after->version, before->version) << "forgetting publishes";
  EXPECT_LT(SumOfAbsLogOdds(*after->tree), 0.75 * evidence_before)
      << "five of the six periods are history and decay; the open one stays";
}

TEST_F(FusionWorkerTest, ARendererBehindGetsCloudsMergedNeverDropped) {
  // At 2 cm an SR-3000 of 88 x 72 beams renders far slower than a cloud integrates: 20 clouds
  // queued at once from 20 poses outrun the renderer, which may have two sealed periods waiting.
  WorkerOptions options = Options();
  options.map.resolution_m = options.map.render.resolution_m = 0.02;
  StartWorker(88, 72, options);
  constexpr int kClouds = 20;
  for (int k = 0; k < kClouds; ++k) {
    ASSERT_TRUE(queues_.Push(Driving(*tessellation_, k), &never_));
  }
  worker_->Stop();
  const auto& counters = *queues_.counters("s");
  EXPECT_EQ(counters.dropped.load(), 0u);
  EXPECT_EQ(counters.integrated.load(), static_cast<std::uint64_t>(kClouds));
  EXPECT_GT(counters.merged.load(), 0u) << "the renderer kept up with 20 queued clouds?";
  EXPECT_EQ(worker_->in_map(), static_cast<std::uint64_t>(kClouds)) << "every cloud in the map";
  EXPECT_LT(worker_->renders(), static_cast<std::uint64_t>(kClouds));
}

// While the renderer reads one sensor's open period, the integrator holds that sensor's next
// cloud and goes on with the other sensors' clouds; the held cloud joins the period after the
// render. ("a" comes before "b" in every batch the integrator takes from the queues.)
TEST_F(FusionWorkerTest, AnotherSensorsCloudIsIntegratedWhileOnesPeriodRenders) {
  worker_->Stop();
  worker_.reset();
  WorkerOptions options = Options();
  options.map.resolution_m = options.map.render.resolution_m = 0.02;
  // A full SR-3000 frame traced ray by ray at 2 cm: a render of a good part of a second.
  options.map.render.method = RenderMethod::kRayTraced;
  SensorSetup slow, fast;
  slow.id = "a";
  slow.spec = *SensorPreset("sr3000");
  fast.id = "b";
  fast.spec = sensor_.spec;  // 16 x 12 beams
  IngestQueues queues{{{"a", 8}, {"b", 8}}};
  SnapshotHub hub{SnapshotHub::kDefaultMaxLoggedRegions, 0.02};
  FusionWorker worker(options, {slow, fast}, &queues, &hub);
  ASSERT_TRUE(worker.Start(nullptr).ok());
  const auto cloud_of = [](const SensorSetup& sensor, std::uint64_t seq) {
    Cloud cloud = WallAt(BeamTessellation(sensor.spec), 2.0, seq);
    cloud.sensor_id = sensor.id;
    return cloud;
  };
  const auto& a = *queues.counters("a");
  const auto& b = *queues.counters("b");
  const auto wait_for = [](const std::atomic<std::uint64_t>& n, std::uint64_t value) {
    const auto end = std::chrono::steady_clock::now() + 60s;
    while (n.load() < value && std::chrono::steady_clock::now() < end) {
      std::this_thread::sleep_for(1ms);
    }
    return n.load();
  };
  ASSERT_TRUE(queues.Push(cloud_of(slow, 1), &never_));
  ASSERT_EQ(wait_for(a.integrated, 1), 1u);
  // The renderer takes up the new period at once (its first frame) and reads it for ~0.8 s.
  std::this_thread::sleep_for(100ms);
  ASSERT_TRUE(queues.Push(cloud_of(slow, 2), &never_));  // the same pose: joins that period
  ASSERT_TRUE(queues.Push(cloud_of(fast, 1), &never_));
  ASSERT_EQ(wait_for(b.integrated, 1), 1u);
  EXPECT_EQ(a.integrated.load(), 1u) << "the other sensor's cloud waited behind the render";
  EXPECT_EQ(wait_for(a.integrated, 2), 2u) << "the held cloud is integrated after the render";
  worker.Stop();
  EXPECT_EQ(worker.in_map(), 3u);
}

// A camera whose intrinsics come from its CameraInfo has no beams before it: a cloud then is
// counted as rejected (no_camera_info), not integrated; after DefineSensor clouds map.
TEST_F(FusionWorkerTest, ACloudBeforeTheCameraInfoIsCountedAsRejected) {
  worker_->Stop();
  sensor_.intrinsics_from_camera_info = true;
  worker_ = std::make_unique<FusionWorker>(Options(), std::vector<SensorSetup>{sensor_}, &queues_,
                                           &hub_);
  ASSERT_TRUE(worker_->Start(nullptr).ok());
  const auto& rejected = queues_.counters("s")->rejected;
  const auto no_camera_info = [&] {
    return rejected.by_reason[static_cast<std::size_t>(RejectReason::kNoCameraInfo)].load();
  };
  ASSERT_TRUE(queues_.Push(WallAt(*tessellation_, 2.0, ++seq_), &never_));
  const auto end = std::chrono::steady_clock::now() + 20s;
  while (no_camera_info() == 0 && std::chrono::steady_clock::now() < end) {
    std::this_thread::sleep_for(5ms);
  }
  EXPECT_EQ(no_camera_info(), 1u);
  EXPECT_EQ(rejected.Total(), 1u);
  EXPECT_EQ(worker_->in_map(), 0u);
  ASSERT_TRUE(worker_->DefineSensor("s", sensor_.spec).ok());
  --seq_;  // in_map counts the clouds integrated
  Feed(2.0, 1);
  EXPECT_EQ(no_camera_info(), 1u);
}

}  // namespace
}  // namespace fusion::service
