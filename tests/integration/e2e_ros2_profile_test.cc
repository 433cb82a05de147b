// The compose profile ros2 (docker/compose.yaml: fusiond-ros2 and sensor-ros2-sim) run
// natively: fusiond with the profile's own configuration (docker/fusiond-ros2.pbtxt; --listen,
// --dds-domain and --snapshot override the container's address, domain and volume, and the
// embedded loopback DDS configuration stands in for docker/cyclonedds-host.xml, which would
// leave loopback), the simulated SR-3000 as sensor-ros2-sim runs it, and a Fast DDS participant
// configured as docs/ros2.md tells ROS 2 nodes (docker/fastdds-loopback.xml) subscribing as RViz
// does: the board appears in /octomap_binary and /octomap_point_cloud_centers.
#include <gtest/gtest.h>
#include <octomap/OcTree.h>

#include <chrono>
#include <cmath>
#include <csignal>
#include <cstring>
#include <memory>
#include <string>

#include "../support/e2e_service.h"

#if FUSION_HAVE_FASTDDS
#include "../support/fastdds_octomap.h"
#include "sensor_msgsPubSubTypes.h"
#endif

namespace {

using namespace std::chrono_literals;
using fusion::testing::E2eService;
using fusion::testing::Subprocess;

// The paper's board faces the sensor at x = 1.75 m.
constexpr double kBoardX = 1.75;
constexpr double kBoardTolerance = 0.05;
// Occupied voxels (or centres) near the board that show it is there, not a speckle.
constexpr int kBoardEvidence = 50;

class E2eRos2ProfileTest : public E2eService {};

#if FUSION_HAVE_FASTDDS
using fusion::testing::FastDdsParticipant;
using fusion::testing::Octomap;
using fusion::testing::TakeNewest;
using PointCloud2 = sensor_msgs::msg::dds_::PointCloud2_;

int OccupiedNearTheBoard(const octomap::OcTree& tree) {
  int near = 0;
  for (auto it = tree.begin_leafs(), end = tree.end_leafs(); it != end; ++it) {
    near += tree.isNodeOccupied(*it) && std::abs(it.getX() - kBoardX) < kBoardTolerance ? 1 : 0;
  }
  return near;
}

int CentresNearTheBoard(const PointCloud2& cloud) {
  int near = 0;
  for (std::size_t i = 0; i < cloud.width(); ++i) {
    float x = 0;
    std::memcpy(&x, cloud.data().data() + i * cloud.point_step(), sizeof x);
    near += std::abs(x - kBoardX) < kBoardTolerance ? 1 : 0;
  }
  return near;
}

TEST_F(E2eRos2ProfileTest, ARos2SubscriberSeesTheBoardInTheMapAndItsCentres) {
  ASSERT_NO_FATAL_FAILURE(StartFusiondWithFile(
      fusion::testing::kRepoDir + "/docker/fusiond-ros2.pbtxt", {"--snapshot", dir_ + "/map.ot"}));
  FastDdsParticipant rviz(domain_, fusion::testing::kRepoDir + "/docker/fastdds-loopback.xml",
                          "fusion_loopback");
  ASSERT_TRUE(rviz.ok());
  auto* binary_reader =
      rviz.CreateReader<octomap_msgs::msg::dds_::Octomap_PubSubType>("rt/octomap_binary");
  auto* centres_reader = rviz.CreateReader<sensor_msgs::msg::dds_::PointCloud2_PubSubType>(
      "rt/octomap_point_cloud_centers");
  ASSERT_TRUE(binary_reader && centres_reader);
  Subprocess sensor({fusion::testing::kToolsDir + "fusion-sim-sensor", "--preset", "sr3000",
                     "--rate", "5", "--domain", std::to_string(domain_), "--scene", "paper-board"});
  ASSERT_TRUE(sensor.started());

  // The profile publishes at 1 Hz: the board shows within a few publications.
  Octomap map;
  PointCloud2 centres;
  int map_evidence = 0, centres_evidence = 0;
  for (const auto end = std::chrono::steady_clock::now() + 40s;
       (map_evidence < kBoardEvidence || centres_evidence < kBoardEvidence) &&
       std::chrono::steady_clock::now() < end;) {
    if (TakeNewest(binary_reader, &map, 500ms)) {
      const auto tree = fusion::testing::MsgToMap(map);
      ASSERT_TRUE(tree) << "octomap_msgs::msgToMap could not read id '" << map.id() << "'";
      map_evidence = OccupiedNearTheBoard(*tree);
    }
    if (TakeNewest(centres_reader, &centres, 500ms))
      centres_evidence = CentresNearTheBoard(centres);
  }
  EXPECT_GE(map_evidence, kBoardEvidence) << "occupied voxels at the board in /octomap_binary";
  EXPECT_GE(centres_evidence, kBoardEvidence) << "centres at the board";
  EXPECT_TRUE(map.binary());
  EXPECT_EQ(map.header().frame_id(), "map");
  EXPECT_DOUBLE_EQ(map.resolution(), 0.02);
  EXPECT_EQ(centres.header().frame_id(), "map");

  EXPECT_EQ(sensor.Stop(SIGTERM, 10000ms), 0);
  EXPECT_EQ(fusiond_->Stop(SIGTERM, 20000ms), 0);
}
#else
TEST_F(E2eRos2ProfileTest, SkippedWithoutFastDds) {
  GTEST_SKIP() << "Fast DDS (libfastrtps-dev, libfastcdr-dev, fastddsgen) was not found at build "
                  "time";
}
#endif

}  // namespace
