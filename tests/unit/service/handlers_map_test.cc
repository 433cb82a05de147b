// GetStats, ListSensors, InspectBeam, ResetMap and SaveMap handlers over an in-process channel
// (handler_fixture.h), bad arguments included.
#include <filesystem>

#include "fusion/service/persistence.h"
#include "handler_fixture.h"

namespace fusion::service::testing {
namespace {

using grpc::StatusCode;

TEST_F(HandlerTest, GetStatsCountsTheCloudsAndDescribesTheMap) {
  const v1::Stats empty = Stats();
  EXPECT_EQ(empty.clouds_received(), 0u);
  EXPECT_EQ(empty.map_leaves(), 0u);
  EXPECT_DOUBLE_EQ(empty.resolution_m(), kResolutionM);
  SeeWall(4);
  const v1::Stats stats = Stats();
  EXPECT_EQ(stats.clouds_received(), 4u);
  EXPECT_EQ(stats.clouds_integrated(), 4u);
  EXPECT_EQ(stats.clouds_in_map(), 4u);
  EXPECT_EQ(stats.clouds_rejected(), 0u);
  EXPECT_GT(stats.map_version(), empty.map_version());
  EXPECT_GT(stats.map_leaves(), 100u);
  EXPECT_GT(stats.map_memory_bytes(), 0u);
  EXPECT_GT(stats.sensor_memory_bytes(), 0u);
  EXPECT_EQ(stats.snapshots_failed(), 0u);
  // The sizes GetStats reports are OctoMap's own figures for the version's tree.
  const auto snapshot = stack_->state()->hub->Current();
  EXPECT_EQ(snapshot->sizes().leaves, snapshot->tree->getNumLeafNodes());
  EXPECT_EQ(snapshot->sizes().memory_bytes, snapshot->tree->memoryUsage());
}

TEST_F(HandlerTest, ListSensorsGivesTheConfiguredSensorAndItsCounters) {
  SeeWall(2);
  v1::ListSensorsResponse reply;
  ASSERT_TRUE(Unary(&v1::FusionMap::Stub::ListSensors, v1::ListSensorsRequest(), &reply).ok());
  ASSERT_EQ(reply.sensors_size(), 1);
  const auto& cam = reply.sensors(0);
  EXPECT_EQ(cam.id(), "cam");
  EXPECT_EQ(cam.preset(), "sr3000");
  EXPECT_EQ(cam.cols(), 22u);
  EXPECT_EQ(cam.rows(), 18u);
  EXPECT_EQ(cam.beams(), 22u * 18u);
  EXPECT_GT(cam.cells_per_beam(), 0u);
  EXPECT_EQ(cam.counters().received(), 2u);
  EXPECT_EQ(cam.counters().integrated(), 2u);
  EXPECT_EQ(cam.counters().last_sequence_number(), 2u);
  EXPECT_EQ(cam.counters().points_updated(), 2u * 22u * 18u);
}

TEST_F(HandlerTest, InspectBeamShowsTheWallOnTheBeam) {
  SeeWall(3);
  v1::InspectBeamResponse reply;
  // Row and column of the beam next to the optical axis.
  ASSERT_TRUE(InspectBeam("sensor_id: \"cam\" row: 9 col: 11", &reply).ok());
  EXPECT_EQ(reply.beam(), 9u * 22u + 11u);
  EXPECT_TRUE(reply.touched());
  ASSERT_GT(reply.cell_occupancy_size(), 0);
  // The most likely cell holds the wall, at its range along the beam.
  int best = 0;
  for (int i = 1; i < reply.cell_occupancy_size(); ++i) {
    if (reply.cell_occupancy(i) > reply.cell_occupancy(best)) best = i;
  }
  const double range_m = kWallZ / reply.direction().z();
  EXPECT_NEAR((best + 0.5) * reply.cell_size_m(), range_m, 0.1);
  ASSERT_TRUE(InspectBeam("sensor_id: \"cam\" beam: 0", &reply).ok());
  EXPECT_EQ(reply.beam(), 0u);
}

TEST_F(HandlerTest, InspectBeamRefusesMissingAndUnknownSensorsAndBeams) {
  v1::InspectBeamResponse reply;
  EXPECT_EQ(InspectBeam("", &reply).error_code(), StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(InspectBeam("sensor_id: \"nobody\"", &reply).error_code(), StatusCode::NOT_FOUND);
  EXPECT_EQ(InspectBeam("sensor_id: \"cam\" beam: 396", &reply).error_code(),
            StatusCode::NOT_FOUND);  // 22 x 18 = 396 beams
  EXPECT_EQ(InspectBeam("sensor_id: \"cam\" row: 18", &reply).error_code(), StatusCode::NOT_FOUND);
  EXPECT_EQ(InspectBeam("sensor_id: \"cam\" col: 22", &reply).error_code(), StatusCode::NOT_FOUND);
}

TEST_F(HandlerTest, ResetMapEmptiesTheMapAndMovesTheVersionOn) {
  SeeWall(3);
  ASSERT_EQ(StateAt(kOnWall), v1::VOXEL_STATE_OCCUPIED);
  const std::uint64_t before = Stats().map_version();
  v1::ResetMapResponse reply;
  ASSERT_TRUE(Unary(&v1::FusionMap::Stub::ResetMap, v1::ResetMapRequest(), &reply).ok());
  EXPECT_GT(reply.map_version(), before);
  EXPECT_EQ(StateAt(kOnWall), v1::VOXEL_STATE_UNKNOWN);
  EXPECT_EQ(StateAt(kInFront), v1::VOXEL_STATE_UNKNOWN);
  EXPECT_EQ(Stats().map_leaves(), 0u);
  SeeWall(3);  // and the map builds again
  EXPECT_EQ(StateAt(kOnWall), v1::VOXEL_STATE_OCCUPIED);
}

TEST_F(HandlerTest, SaveMapWithoutPersistenceIsAFailedPrecondition) {
  v1::SaveMapResponse reply;
  const auto status = Unary(&v1::FusionMap::Stub::SaveMap, v1::SaveMapRequest(), &reply);
  EXPECT_EQ(status.error_code(), StatusCode::FAILED_PRECONDITION);
  EXPECT_NE(status.error_message().find("persistence.path"), std::string::npos);
}

TEST_F(HandlerTest, SaveMapWritesTheCurrentMap) {
  const std::string dir = ::testing::TempDir() + "handlers_save_" + std::to_string(::getpid());
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  const std::string path = dir + "/map.ot";
  TearDown();
  StartService("persistence { path: \"" + path + "\" interval_s: 3600 }");
  SeeWall(3);
  v1::SaveMapResponse reply;
  const auto status = Unary(&v1::FusionMap::Stub::SaveMap, v1::SaveMapRequest(), &reply);
  ASSERT_TRUE(status.ok()) << status.error_message();
  EXPECT_EQ(reply.path(), path);
  EXPECT_EQ(reply.bytes(), std::filesystem::file_size(path));
  EXPECT_EQ(reply.map_version(), Stats().map_version());
  EXPECT_EQ(Stats().snapshots_saved(), 1u);
  std::unique_ptr<octomap::OcTree> loaded;
  std::string message;
  ASSERT_EQ(LoadSnapshotFile(path, kResolutionM, &loaded, &message), LoadStatus::kLoaded)
      << message;
  EXPECT_EQ(loaded->getNumLeafNodes(), Stats().map_leaves());
  TearDown();
  stack_.reset();
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace fusion::service::testing
