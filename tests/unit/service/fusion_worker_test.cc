// FusionWorker: the published map follows the live map, including voxels that lose their
// information (deleted from the published octree, not left behind).
#include "fusion/service/fusion_worker.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <thread>

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

class FusionWorkerTest : public ::testing::Test {
 protected:
  void SetUp() override {
    SensorSetup sensor;
    sensor.id = "s";
    sensor.spec = *SensorPreset("sr3000");
    sensor.spec.cols = 16;
    sensor.spec.rows = 12;
    tessellation_ = std::make_unique<BeamTessellation>(sensor.spec);
    WorkerOptions options;
    options.map.resolution_m = kResolutionM;
    options.map.render.resolution_m = kResolutionM;
    options.map.render.max_range_m = 4.0;
    options.render_interval = 10ms;
    options.nice = 0;
    worker_ = std::make_unique<FusionWorker>(options, std::vector<SensorSetup>{sensor}, &queues_,
                                             &hub_);
    std::string error;
    ASSERT_TRUE(worker_->Start(nullptr, &error)) << error;
  }
  void TearDown() override { worker_->Stop(); }

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

  static const octomap::OcTreeNode* On(const octomap::OcTree& tree, double z_m) {
    return tree.search(0.01, 0.01, z_m);
  }

  IngestQueues queues_{{{"s", 64}}};
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

}  // namespace
}  // namespace fusion::service
