// FindPlanes, GetSnapshot, StreamUpdates and ClearBox handlers over an in-process channel
// (handler_fixture.h): the wall's plane, a snapshot that reads back as the map, update streams
// that start with the whole map and follow it, a cleared box its followers are told of, and the
// bad arguments and limits of each.
#include <octomap/OcTree.h>

#include <sstream>

#include "handler_fixture.h"

namespace fusion::service::testing {
namespace {

using grpc::StatusCode;

TEST_F(HandlerTest, FindPlanesFindsTheWall) {
  SeeWall(3);
  v1::FindPlanesResponse reply;
  const auto status = FindPlanes("max_planes: 2 min_support_voxels: 30", &reply);
  ASSERT_TRUE(status.ok()) << status.error_message();
  ASSERT_GE(reply.planes_size(), 1);
  const v1::Plane& wall = reply.planes(0);
  EXPECT_GT(std::abs(wall.normal().z()), 0.99) << wall.ShortDebugString();
  EXPECT_NEAR(std::abs(wall.d_m()), kWallZ, 1.5 * kResolutionM) << wall.ShortDebugString();
  EXPECT_GE(wall.support_voxels(), 30u);
  EXPECT_EQ(reply.map_version(), Stats().map_version());
  // A region that holds only free space has no plane.
  ASSERT_TRUE(FindPlanes("region_min { x: -1 y: -1 z: 0.5 } region_max { x: 1 y: 1 z: 1.5 }",
                         &reply)
                  .ok());
  EXPECT_EQ(reply.planes_size(), 0);
}

TEST_F(HandlerTest, FindPlanesRefusesBadArguments) {
  v1::FindPlanesResponse reply;
  const auto code = [&](const std::string& text) { return FindPlanes(text, &reply).error_code(); };
  EXPECT_EQ(code("region_min { x: 0 }"), StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(code("region_min { x: 2 } region_max { x: 1 }"), StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(code("region_min { x: nan } region_max { x: 1 }"), StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(code("max_planes: 65"), StatusCode::RESOURCE_EXHAUSTED);
  EXPECT_EQ(code("min_probability: 1"), StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(code("min_probability: -0.1"), StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(code("angle_step_deg: 0.05"), StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(code("angle_step_deg: 46"), StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(code("distance_step_m: 0.0005"), StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(code("distance_step_m: 11"), StatusCode::INVALID_ARGUMENT);
}

TEST_F(HandlerTest, FindPlanesRefusesASearchAboveTheAccumulatorLimit) {
  TearDown();
  StartService("limits { max_plane_cells: 100000 }");
  SeeWall(1);
  v1::FindPlanesResponse reply;
  const auto status = FindPlanes("angle_step_deg: 0.5 distance_step_m: 0.001", &reply);
  EXPECT_EQ(status.error_code(), StatusCode::RESOURCE_EXHAUSTED);
  EXPECT_NE(status.error_message().find("limits.max_plane_cells"), std::string::npos);
}

// The chunks of one GetSnapshot call, checked to be contiguous, and the call's status.
grpc::Status ReadSnapshot(v1::FusionMap::Stub* stub, const std::string& request_text,
                          std::string* bytes, std::uint64_t* version) {
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + 20s);
  auto reader = stub->GetSnapshot(&context, Text<v1::GetSnapshotRequest>(request_text));
  v1::SnapshotChunk chunk;
  std::uint64_t total = 0;
  while (reader->Read(&chunk)) {
    EXPECT_EQ(chunk.offset(), bytes->size());
    if (bytes->empty()) total = chunk.total_bytes(), *version = chunk.map_version();
    EXPECT_EQ(chunk.total_bytes(), total);
    EXPECT_EQ(chunk.map_version(), *version);
    *bytes += chunk.data();
  }
  const grpc::Status status = reader->Finish();
  if (status.ok()) {
    EXPECT_EQ(bytes->size(), total);
  }
  return status;
}

TEST_F(HandlerTest, GetSnapshotStreamsTheMapInBothFormats) {
  TearDown();
  StartService("limits { snapshot_chunk_bytes: 1024 }");  // many chunks
  SeeWall(3);
  const v1::Stats stats = Stats();
  std::string ot, bt;
  std::uint64_t version = 0;
  ASSERT_TRUE(ReadSnapshot(stub_.get(), "format: FORMAT_OT", &ot, &version).ok());
  EXPECT_EQ(version, stats.map_version());
  EXPECT_GT(ot.size(), 2048u);
  std::istringstream ot_stream(ot);
  std::unique_ptr<octomap::AbstractOcTree> tree(octomap::AbstractOcTree::read(ot_stream));
  auto* full = dynamic_cast<octomap::OcTree*>(tree.get());
  ASSERT_NE(full, nullptr);
  EXPECT_EQ(full->getNumLeafNodes(), stats.map_leaves());
  EXPECT_DOUBLE_EQ(full->getResolution(), kResolutionM);

  ASSERT_TRUE(ReadSnapshot(stub_.get(), "format: FORMAT_BT", &bt, &version).ok());
  std::istringstream bt_stream(bt);
  octomap::OcTree binary(0.1);
  ASSERT_TRUE(binary.readBinary(bt_stream));
  EXPECT_DOUBLE_EQ(binary.getResolution(), kResolutionM);
  const octomap::OcTreeNode* wall = binary.search(kOnWall.x(), kOnWall.y(), kOnWall.z());
  ASSERT_NE(wall, nullptr);
  EXPECT_TRUE(binary.isNodeOccupied(wall));
}

TEST_F(HandlerTest, GetSnapshotRefusesAnUnknownFormat) {
  std::string bytes;
  std::uint64_t version = 0;
  EXPECT_EQ(ReadSnapshot(stub_.get(), "format: 9", &bytes, &version).error_code(),
            StatusCode::INVALID_ARGUMENT);
}

// Reads updates until one with complete = true; all of them appended to *updates.
bool ReadBatch(grpc::ClientReader<v1::MapUpdate>* reader, std::vector<v1::MapUpdate>* updates) {
  v1::MapUpdate update;
  while (reader->Read(&update)) {
    updates->push_back(update);
    if (update.complete()) return true;
  }
  return false;
}

TEST_F(HandlerTest, StreamUpdatesStartsWithTheWholeMapThenFollowsIt) {
  SeeWall(2);
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + 20s);
  auto reader = stub_->StreamUpdates(&context, Text<v1::StreamUpdatesRequest>("since_version: 0"));
  std::vector<v1::MapUpdate> first;
  ASSERT_TRUE(ReadBatch(reader.get(), &first));
  std::size_t voxels = 0;
  bool wall_seen = false;
  for (const auto& u : first) {
    EXPECT_TRUE(u.full());
    voxels += static_cast<std::size_t>(u.voxels_size());
    for (const auto& v : u.voxels()) {
      wall_seen |= v.state() == v1::VOXEL_STATE_OCCUPIED &&
                   std::abs(v.center().z() - kWallZ) < v.size_m() / 2 + 1e-9 &&
                   std::abs(v.center().x()) < v.size_m() && std::abs(v.center().y()) < v.size_m();
    }
  }
  EXPECT_EQ(voxels, Stats().map_leaves());
  EXPECT_TRUE(wall_seen);
  const std::uint64_t seen = first.back().map_version();

  SeeWall(1);  // a new version: the changes since the one the subscriber has
  std::vector<v1::MapUpdate> next;
  ASSERT_TRUE(ReadBatch(reader.get(), &next));
  EXPECT_GT(next.back().map_version(), seen);
  EXPECT_FALSE(next.front().full());
  EXPECT_EQ(next.front().from_version(), seen);

  v1::ResetMapResponse reset;
  ASSERT_TRUE(Unary(&v1::FusionMap::Stub::ResetMap, v1::ResetMapRequest(), &reset).ok());
  std::vector<v1::MapUpdate> after_reset;
  bool wall_unknown = false;
  std::size_t full_voxels = 0;
  bool full = false;
  while (!(after_reset.empty() ? false : after_reset.back().map_version() >= reset.map_version())) {
    ASSERT_TRUE(ReadBatch(reader.get(), &after_reset));
  }
  for (const auto& u : after_reset) {
    full |= u.full();
    if (u.full()) full_voxels += static_cast<std::size_t>(u.voxels_size());
    for (const auto& v : u.voxels()) {
      wall_unknown |= v.state() == v1::VOXEL_STATE_UNKNOWN &&
                      std::abs(v.center().z() - kWallZ) < v.size_m() / 2 + 1e-9;
    }
  }
  // The wall's voxels are told to be unknown now, or the whole (empty) map is sent again.
  EXPECT_TRUE(wall_unknown || (full && full_voxels == 0));
  context.TryCancel();
}

TEST_F(HandlerTest, ClearBoxForgetsTheBoxAndTellsTheFollowers) {
  SeeWall(3);
  const Eigen::Vector3d beside_box(0.6, 0.0, kWallZ);
  ASSERT_EQ(StateAt(kOnWall), v1::VOXEL_STATE_OCCUPIED);
  ASSERT_EQ(StateAt(beside_box), v1::VOXEL_STATE_OCCUPIED);
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + 20s);
  auto reader = stub_->StreamUpdates(&context, Text<v1::StreamUpdatesRequest>("since_version: 0"));
  std::vector<v1::MapUpdate> updates;
  ASSERT_TRUE(ReadBatch(reader.get(), &updates));

  v1::ClearBoxResponse reply;
  const auto status = Unary(&v1::FusionMap::Stub::ClearBox,
                            Text<v1::ClearBoxRequest>("min { x: -0.3 y: -0.3 z: 1.9 } "
                                                      "max { x: 0.3 y: 0.3 z: 2.2 }"),
                            &reply);
  ASSERT_TRUE(status.ok()) << status.error_message();
  EXPECT_GT(reply.map_version(), updates.back().map_version());
  EXPECT_GT(reply.voxels_cleared(), 0u);
  EXPECT_EQ(StateAt(kOnWall), v1::VOXEL_STATE_UNKNOWN);
  EXPECT_EQ(StateAt(beside_box), v1::VOXEL_STATE_OCCUPIED) << "outside the box";
  EXPECT_EQ(StateAt(kInFront), v1::VOXEL_STATE_FREE) << "outside the box";
  // The follower hears of it: the wall's voxels in the box are unknown now.
  updates.clear();
  while (updates.empty() || updates.back().map_version() < reply.map_version()) {
    ASSERT_TRUE(ReadBatch(reader.get(), &updates));
  }
  bool told = false;
  for (const auto& u : updates) {
    for (const auto& v : u.voxels()) {
      const Eigen::Vector3d c(v.center().x(), v.center().y(), v.center().z());
      told |= v.state() == v1::VOXEL_STATE_UNKNOWN &&
              ((c - kOnWall).cwiseAbs().array() <= v.size_m() / 2 + 1e-5).all();  // float centres
    }
  }
  EXPECT_TRUE(told);
  context.TryCancel();
  SeeWall(2);  // the world is still there: new clouds map it again
  EXPECT_EQ(StateAt(kOnWall), v1::VOXEL_STATE_OCCUPIED);
}

TEST_F(HandlerTest, ClearBoxRefusesBadBoxes) {
  for (const char* bad : {"min { x: 1 } max { x: 0 }", "min { x: nan } max { x: 1 }",
                          "min { x: 0 }", "max { x: 1 y: 1 z: 1 }"}) {
    v1::ClearBoxResponse reply;
    const auto status =
        Unary(&v1::FusionMap::Stub::ClearBox, Text<v1::ClearBoxRequest>(bad), &reply);
    EXPECT_EQ(status.error_code(), StatusCode::INVALID_ARGUMENT) << bad;
  }
}

TEST_F(HandlerTest, StreamUpdatesRefusesSubscribersAboveTheLimit) {
  TearDown();
  StartService("limits { max_update_streams: 1 }");
  SeeWall(1);
  grpc::ClientContext first_context, second_context;
  first_context.set_deadline(std::chrono::system_clock::now() + 20s);
  second_context.set_deadline(std::chrono::system_clock::now() + 20s);
  auto first = stub_->StreamUpdates(&first_context, v1::StreamUpdatesRequest());
  v1::MapUpdate update;
  ASSERT_TRUE(first->Read(&update));  // open (the whole map comes first): it holds the one slot
  auto second = stub_->StreamUpdates(&second_context, v1::StreamUpdatesRequest());
  EXPECT_FALSE(second->Read(&update));
  const auto status = second->Finish();
  EXPECT_EQ(status.error_code(), StatusCode::RESOURCE_EXHAUSTED);
  EXPECT_NE(status.error_message().find("limits.max_update_streams"), std::string::npos);
  first_context.TryCancel();
}

}  // namespace
}  // namespace fusion::service::testing
