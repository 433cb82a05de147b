// fusiond end to end: a real fusiond process on 127.0.0.1:0 in a private DDS domain, fed with
// simulated SR-3000 clouds of the paper's board scene over DDS, queried over gRPC. Its
// persistence (snapshots after kill -9, corrupt files, failing writes) is tested in
// fusiond_persistence_test.cc with the same fixture.
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>
#include <octomap/AbstractOcTree.h>
#include <octomap/OcTree.h>
#include <sys/stat.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <functional>
#include <iterator>
#include <memory>
#include <set>
#include <sstream>
#include <string>
#include <thread>
#include <tuple>
#include <utility>
#include <vector>

#include "../support/fusiond_fixture.h"
#include "fusion/core/beam_tessellation.h"
#include "fusion/core/sensor.h"
#include "fusion/sim/scene.h"
#include "fusion/sim/simulator.h"
#include "fusion/v1/map_service.grpc.pb.h"
#include "grpc/health/v1/health.grpc.pb.h"

namespace {

using namespace fusion::testing;  // NOLINT: the fixture and its helpers
using namespace std::chrono_literals;
namespace v1 = fusion::v1;

std::string FetchSnapshot(v1::FusionMap::Stub& stub, v1::GetSnapshotRequest::Format format,
                          std::uint64_t* version) {
  grpc::ClientContext context;
  context.set_deadline(In(10s));
  v1::GetSnapshotRequest request;
  request.set_format(format);
  auto reader = stub.GetSnapshot(&context, request);
  std::string data;
  v1::SnapshotChunk chunk;
  while (reader->Read(&chunk)) {
    EXPECT_EQ(chunk.offset(), data.size());
    data += chunk.data();
    *version = chunk.map_version();
    EXPECT_EQ(chunk.total_bytes(),
              chunk.offset() + chunk.data().size() +
                  (chunk.total_bytes() - chunk.offset() - chunk.data().size()));
  }
  const auto status = reader->Finish();
  EXPECT_TRUE(status.ok()) << status.error_message();
  return data;
}

bool Occupied(const octomap::OcTree& tree, const Eigen::Vector3d& p) {
  const auto* node = tree.search(p.x(), p.y(), p.z());
  return node != nullptr && tree.isNodeOccupied(node);
}

// ---- The steps of SurfacesAppearAndEveryQueryAnswersThem, each on the board that
// MapTheBoard mapped (version `version`); the test calls each in ASSERT_NO_FATAL_FAILURE, so
// that a failed ASSERT in a step ends the test as it did when the steps were inline.

// Snapshot in both OctoMap formats, read back by OctoMap itself.
void ExpectSnapshotsInBothFormatsHoldTheBoard(v1::FusionMap::Stub& stub, std::uint64_t version) {
  std::uint64_t snapshot_version = 0;
  const std::string bt = FetchSnapshot(stub, v1::GetSnapshotRequest::FORMAT_BT, &snapshot_version);
  EXPECT_GE(snapshot_version, version);
  octomap::OcTree from_bt(0.1);
  std::istringstream bt_stream(bt);
  ASSERT_TRUE(from_bt.readBinary(bt_stream));
  EXPECT_DOUBLE_EQ(from_bt.getResolution(), 0.05);
  EXPECT_TRUE(Occupied(from_bt, kOnBoard));
  const std::string ot = FetchSnapshot(stub, v1::GetSnapshotRequest::FORMAT_OT, &snapshot_version);
  std::istringstream ot_stream(ot);
  std::unique_ptr<octomap::AbstractOcTree> from_ot(octomap::AbstractOcTree::read(ot_stream));
  auto* ot_tree = dynamic_cast<octomap::OcTree*>(from_ot.get());
  ASSERT_NE(ot_tree, nullptr);
  EXPECT_TRUE(Occupied(*ot_tree, kOnBoard));
  EXPECT_FALSE(Occupied(*ot_tree, kInFront));
}

// Box query, all pages, equals the occupied leaves of the snapshot in that box.
void ExpectBoxQueryPagesThroughTheBoard(v1::FusionMap::Stub& stub) {
  std::set<std::tuple<double, double, double>> paged;
  std::string token;
  int pages = 0;
  do {
    grpc::ClientContext context;
    context.set_deadline(In(5s));
    v1::QueryBoxRequest request;
    *request.mutable_min() = P({1.5, -1.0, -0.5});
    *request.mutable_max() = P({2.0, 1.0, 1.0});
    request.add_states(v1::VOXEL_STATE_OCCUPIED);
    request.set_page_size(50);
    request.set_page_token(token);
    v1::QueryBoxResponse reply;
    ASSERT_TRUE(stub.QueryBox(&context, request, &reply).ok());
    ASSERT_LE(reply.voxels_size(), 50);
    for (const auto& v : reply.voxels()) {
      EXPECT_EQ(v.state(), v1::VOXEL_STATE_OCCUPIED);
      EXPECT_TRUE(paged.emplace(v.center().x(), v.center().y(), v.center().z()).second)
          << "voxel returned twice";
    }
    token = reply.next_page_token();
    ++pages;
  } while (!token.empty() && pages < 1000);
  EXPECT_GT(pages, 1);
  EXPECT_GT(paged.size(), 100u);  // a 1.2 m x 1 m board at 5 cm
}

// A ray from the sensor along +x stops at the board.
void ExpectRayStopsAtTheBoard(v1::FusionMap::Stub& stub) {
  grpc::ClientContext context;
  context.set_deadline(In(5s));
  v1::CastRayRequest request;
  *request.mutable_origin() = P({0.0, 0.0, 0.2});
  *request.mutable_direction() = P({1.0, 0.0, 0.0});
  request.set_max_range_m(5.0);
  request.set_ignore_unknown(true);  // the first 0.6 m (below r_min) are unknown
  v1::CastRayResponse reply;
  ASSERT_TRUE(stub.CastRay(&context, request, &reply).ok());
  EXPECT_TRUE(reply.hit());
  EXPECT_NEAR(reply.end().x(), 1.75, 0.1);
}

// The board is found as a plane facing the sensor (normal along x, 1.75 m away).
void ExpectTheBoardIsAPlane(v1::FusionMap::Stub& stub) {
  grpc::ClientContext context;
  context.set_deadline(In(20s));
  v1::FindPlanesRequest request;
  *request.mutable_region_min() = P({1.0, -1.0, -0.35});
  *request.mutable_region_max() = P({2.5, 1.0, 1.0});
  v1::FindPlanesResponse reply;
  const auto status = stub.FindPlanes(&context, request, &reply);
  ASSERT_TRUE(status.ok()) << status.error_message();
  ASSERT_GT(reply.planes_size(), 0);
  EXPECT_GT(std::abs(reply.planes(0).normal().x()), 0.9);
  EXPECT_NEAR(reply.planes(0).d_m(), 1.75, 0.1);
}

// The centre beam saw the board: its p(B) is a distribution with mass near 1.75 m.
void ExpectTheCentreBeamSawTheBoard(v1::FusionMap::Stub& stub) {
  grpc::ClientContext context;
  context.set_deadline(In(5s));
  v1::InspectBeamRequest request;
  request.set_sensor_id("sr");
  request.set_row(kRows / 2);
  request.set_col(kCols / 2);
  v1::InspectBeamResponse reply;
  ASSERT_TRUE(stub.InspectBeam(&context, request, &reply).ok());
  EXPECT_TRUE(reply.touched());
  // Numbered and pointing as the sensor's beams, not the period's wider grid's.
  const int beam = (kRows / 2) * kCols + kCols / 2;
  EXPECT_EQ(reply.beam(), static_cast<std::uint32_t>(beam));
  const fusion::BeamTessellation tess(
      fusion::sim::WithTessellation(*fusion::SensorPreset("sr3000"), kCols, kRows));
  const Eigen::Vector3d d = tess.Direction(static_cast<std::size_t>(beam));
  EXPECT_NEAR(reply.direction().x(), d.x(), 1e-9);
  EXPECT_NEAR(reply.direction().y(), d.y(), 1e-9);
  EXPECT_NEAR(reply.direction().z(), d.z(), 1e-9);
  ASSERT_EQ(reply.first_hit_size(), reply.cell_occupancy_size() + 1);
  double sum = 0.0, near_board = 0.0;
  for (int i = 0; i < reply.first_hit_size(); ++i) {
    sum += reply.first_hit(i);
    if (std::abs((i + 0.5) * reply.cell_size_m() - 1.75) < 0.1) near_board += reply.first_hit(i);
  }
  EXPECT_NEAR(sum, 1.0, 1e-6);
  // Most of the first-hit mass lies within 10 cm of the board.
  EXPECT_GT(near_board, 0.5) << "p(B) near 1.75 m: " << near_board;
}

// The update stream starts with the whole map.
void ExpectTheUpdateStreamStartsWithTheMap(v1::FusionMap::Stub& stub, std::uint64_t version) {
  grpc::ClientContext context;
  context.set_deadline(In(5s));
  v1::StreamUpdatesRequest request;
  auto reader = stub.StreamUpdates(&context, request);
  v1::MapUpdate update;
  ASSERT_TRUE(reader->Read(&update)) << reader->Finish().error_message();
  EXPECT_TRUE(update.full());
  EXPECT_GE(update.map_version(), version);
  EXPECT_GT(update.voxels_size(), 100);
  context.TryCancel();
  reader->Finish();
}

// A versions-only stream announces the current version, then the version a new frame makes
// (published by publish_frame), without voxels.
void ExpectAVersionsOnlyStreamAnnouncesANewFrame(v1::FusionMap::Stub& stub, std::uint64_t version,
                                                 const std::function<void()>& publish_frame) {
  grpc::ClientContext context;
  context.set_deadline(In(10s));
  v1::StreamUpdatesRequest request;
  request.set_since_version(version);
  request.set_versions_only(true);
  auto reader = stub.StreamUpdates(&context, request);
  v1::MapUpdate update;
  ASSERT_TRUE(reader->Read(&update));
  const std::uint64_t announced = update.map_version();
  EXPECT_GE(announced, version);
  EXPECT_EQ(update.voxels_size(), 0);
  EXPECT_TRUE(update.complete());
  publish_frame();
  ASSERT_TRUE(reader->Read(&update));
  EXPECT_GT(update.map_version(), announced);
  EXPECT_EQ(update.from_version(), announced);
  EXPECT_EQ(update.voxels_size(), 0);
  context.TryCancel();
  reader->Finish();
}

// Saved on request to `snapshot`; OctoMap's own convert_octree reads the file (its output
// goes to `dir`).
void ExpectSaveMapWritesWhatOctoMapReads(v1::FusionMap::Stub& stub, const std::string& snapshot,
                                         const std::string& dir) {
  grpc::ClientContext context;
  context.set_deadline(In(10s));
  v1::SaveMapResponse reply;
  ASSERT_TRUE(stub.SaveMap(&context, v1::SaveMapRequest(), &reply).ok());
  EXPECT_EQ(reply.path(), snapshot);
  const std::string converted = dir + "/converted.bt";
  const std::string command =
      "/usr/bin/convert_octree '" + snapshot + "' '" + converted + "' > /dev/null 2>&1";
  ASSERT_EQ(std::system(command.c_str()), 0);
  octomap::OcTree tree(0.1);
  ASSERT_TRUE(tree.readBinary(converted));
  EXPECT_TRUE(Occupied(tree, kOnBoard));
}

TEST_F(FusiondServiceTest, SurfacesAppearAndEveryQueryAnswersThem) {
  auto fusiond = Start();
  ASSERT_TRUE(fusiond);
  TestPublisher publisher(domain_);
  ASSERT_TRUE(publisher.ok()) << publisher.error();
  ASSERT_TRUE(publisher.WaitForReader(10s));
  const std::uint64_t version = MapTheBoard(publisher);
  ASSERT_GT(version, 0u);

  ASSERT_NO_FATAL_FAILURE(ExpectSnapshotsInBothFormatsHoldTheBoard(*stub_, version));
  ASSERT_NO_FATAL_FAILURE(ExpectBoxQueryPagesThroughTheBoard(*stub_));
  ASSERT_NO_FATAL_FAILURE(ExpectRayStopsAtTheBoard(*stub_));
  ASSERT_NO_FATAL_FAILURE(ExpectTheBoardIsAPlane(*stub_));
  ASSERT_NO_FATAL_FAILURE(ExpectTheCentreBeamSawTheBoard(*stub_));
  ASSERT_NO_FATAL_FAILURE(ExpectTheUpdateStreamStartsWithTheMap(*stub_, version));
  ASSERT_NO_FATAL_FAILURE(ExpectAVersionsOnlyStreamAnnouncesANewFrame(
      *stub_, version, [&] { PublishBoardFrame(publisher, 1000); }));

  const auto counters = SrCounters();
  EXPECT_GT(counters.integrated(), 0u);
  EXPECT_GT(counters.points_updated(), 0u);
  EXPECT_EQ(counters.rejected(), 0u);

  ASSERT_NO_FATAL_FAILURE(ExpectSaveMapWritesWhatOctoMapReads(*stub_, snapshot_, dir_));

  // SIGTERM: exits 0 with a final snapshot; a restart serves the same map without new data.
  EXPECT_EQ(fusiond->Stop(SIGTERM, 15s), 0);
  auto restarted = Start();
  ASSERT_TRUE(restarted);
  EXPECT_EQ(Occupancy(kOnBoard).state(), v1::VOXEL_STATE_OCCUPIED);
  EXPECT_EQ(Occupancy(kInFront).state(), v1::VOXEL_STATE_FREE);
  EXPECT_EQ(restarted->Stop(SIGTERM, 15s), 0);
}

// Update streams are bounded: at most limits.max_update_streams at once (one more gets
// RESOURCE_EXHAUSTED, a closed one frees its place), and a full resend goes page by page, all of
// the map's leaves in order, the last page complete.
TEST_F(FusiondServiceTest, UpdateStreamsAreLimitedAndResendTheMapPageByPage) {
  {
    std::ifstream in(config_);
    std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    const std::string limits = "limits { ";
    text.replace(text.find(limits), limits.size(), "limits { max_update_streams: 2 ");
    const std::string page = "max_voxels_per_page: 50000";
    text.replace(text.find(page), page.size(), "max_voxels_per_page: 200");
    std::ofstream(config_) << text;
  }
  auto fusiond = Start();
  ASSERT_TRUE(fusiond);
  {
    TestPublisher publisher(domain_);
    ASSERT_TRUE(publisher.WaitForReader(10s));
    ASSERT_GT(MapTheBoard(publisher), 0u);
  }
  // Let the last render publish: then the map stays as it is.
  std::uint64_t version = 0;
  for (int i = 0; i < 50 && Stats().map_version() != version; ++i) {
    version = Stats().map_version();
    std::this_thread::sleep_for(300ms);
  }
  const v1::Stats stats = Stats();
  ASSERT_EQ(stats.map_version(), version);
  ASSERT_GT(stats.map_leaves(), 1000u);

  grpc::ClientContext first_context;
  first_context.set_deadline(In(20s));
  auto first = stub_->StreamUpdates(&first_context, v1::StreamUpdatesRequest());
  std::uint64_t voxels = 0, pages = 0;
  v1::MapUpdate update;
  while (first->Read(&update)) {
    EXPECT_TRUE(update.full());
    EXPECT_EQ(update.map_version(), version);
    EXPECT_LE(update.voxels_size(), 200);
    voxels += static_cast<std::uint64_t>(update.voxels_size());
    ++pages;
    if (update.complete()) break;
  }
  ASSERT_TRUE(update.complete());
  EXPECT_EQ(voxels, stats.map_leaves());
  EXPECT_GE(pages, stats.map_leaves() / 200);

  grpc::ClientContext second_context;
  second_context.set_deadline(In(20s));
  v1::StreamUpdatesRequest versions_only;
  versions_only.set_versions_only(true);
  auto second = stub_->StreamUpdates(&second_context, versions_only);
  ASSERT_TRUE(second->Read(&update));
  {
    grpc::ClientContext third_context;
    third_context.set_deadline(In(5s));
    auto third = stub_->StreamUpdates(&third_context, versions_only);
    EXPECT_FALSE(third->Read(&update));
    const grpc::Status status = third->Finish();
    EXPECT_EQ(status.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED) << status.error_message();
  }
  first_context.TryCancel();
  (void)first->Finish();
  // The cancelled stream's place is free again (the server learns of it asynchronously).
  bool reopened = false;
  for (int i = 0; i < 50 && !reopened; ++i) {
    grpc::ClientContext context;
    context.set_deadline(In(5s));
    auto again = stub_->StreamUpdates(&context, versions_only);
    reopened = again->Read(&update);
    context.TryCancel();
    (void)again->Finish();
    if (!reopened) std::this_thread::sleep_for(100ms);
  }
  EXPECT_TRUE(reopened);
  second_context.TryCancel();
  (void)second->Finish();
  EXPECT_EQ(fusiond->Stop(SIGTERM, 15s), 0);
}

// A valid two-point cloud of sensor "sr", and the malformations MalformedCloudsAreRejected...
// publishes, each with the reason fusiond counts it under.
TestCloud GoodCloud() {
  TestCloud c;
  c.width = 2;
  c.xyz = {0.f, 0.f, 1.5f, 0.1f, 0.f, 1.5f};
  return c;
}

std::vector<std::pair<std::string, TestCloud>> MalformedClouds() {
  std::vector<std::pair<std::string, TestCloud>> bad;
  bad.emplace_back("point_count_mismatch", GoodCloud());
  bad.back().second.xyz.pop_back();
  bad.emplace_back("beyond_range_mismatch", GoodCloud());
  bad.back().second.beyond_range = {0, 0, 1};
  bad.emplace_back("non_finite_pose", GoodCloud());
  bad.back().second.tx = NAN;
  bad.emplace_back("non_unit_quaternion", GoodCloud());
  bad.back().second.qw = 0.5;
  bad.emplace_back("absurd_point_count", GoodCloud());
  bad.back().second.width = 1000;
  bad.back().second.height = 1000;
  bad.emplace_back("absurd_translation", GoodCloud());
  bad.back().second.tz = 1e9;
  // 5 km away: within ingest.max_abs_translation_m, but beyond the map's keys at 5 cm
  // (+-1638.4 m), where its voxels would wrap around to x = 5000 - 3276.8 m.
  bad.emplace_back("outside_map", GoodCloud());
  bad.back().second.tx = 5000.0;
  bad.emplace_back("unknown_sensor", GoodCloud());
  bad.back().second.sensor_id = "ghost";
  return bad;
}

TEST_F(FusiondServiceTest, MalformedCloudsAreRejectedWhileServing) {
  auto fusiond = Start();
  ASSERT_TRUE(fusiond);
  TestPublisher publisher(domain_);
  ASSERT_TRUE(publisher.WaitForReader(10s));

  // One valid cloud first: once it is integrated, both sides have discovered each other.
  auto warm_up = GoodCloud();
  const auto warm_end = std::chrono::steady_clock::now() + 10s;
  while (SrCounters().integrated() == 0 && std::chrono::steady_clock::now() < warm_end) {
    ASSERT_TRUE(publisher.Publish(warm_up));
    std::this_thread::sleep_for(100ms);
  }
  const std::uint64_t integrated_before = SrCounters().integrated();
  ASSERT_GT(integrated_before, 0u);
  auto bad = MalformedClouds();
  for (auto& [reason, cloud] : bad) {
    ASSERT_TRUE(publisher.Publish(cloud)) << reason;
    std::this_thread::sleep_for(50ms);
  }
  auto valid = GoodCloud();
  valid.sequence_number = 99;
  ASSERT_TRUE(publisher.Publish(valid));

  // Counted per reason, on the sensor and in the stats; the valid cloud still integrates.
  v1::SensorCounters counters;
  const auto end = std::chrono::steady_clock::now() + 10s;
  while (std::chrono::steady_clock::now() < end) {
    counters = SrCounters();
    if (counters.rejected() == 7 && counters.integrated() == integrated_before + 1) break;
    std::this_thread::sleep_for(50ms);
  }
  EXPECT_EQ(counters.rejected(), 7u);
  EXPECT_EQ(counters.integrated(), integrated_before + 1);
  EXPECT_EQ(counters.last_sequence_number(), 99u);
  for (const auto& [reason, cloud] : bad) {
    if (reason == "unknown_sensor") continue;
    EXPECT_EQ(
        counters.rejected_by_reason().count(reason) ? counters.rejected_by_reason().at(reason) : 0,
        1u)
        << reason;
  }
  const auto stats = Stats();
  EXPECT_EQ(stats.clouds_rejected(), 8u);
  // Nothing of the far cloud was written where its voxels would have wrapped to.
  EXPECT_EQ(Occupancy({5000.0 - 2 * 1638.4, 0.0, 1.5}).state(), v1::VOXEL_STATE_UNKNOWN);
  ASSERT_EQ(stats.rejected_by_reason().count("unknown_sensor"), 1u);
  EXPECT_EQ(stats.rejected_by_reason().at("unknown_sensor"), 1u);

  // Bad requests get the status code that fits: tests/unit/service/handlers_*_test.cc.

  // Still healthy and serving.
  auto health = grpc::health::v1::Health::NewStub(channel_);
  grpc::ClientContext context;
  context.set_deadline(In(5s));
  grpc::health::v1::HealthCheckResponse reply;
  ASSERT_TRUE(health->Check(&context, grpc::health::v1::HealthCheckRequest(), &reply).ok());
  EXPECT_EQ(reply.status(), grpc::health::v1::HealthCheckResponse::SERVING);
  EXPECT_EQ(fusiond->Stop(SIGTERM, 15s), 0);
}

TEST_F(FusiondServiceTest, RefusesABadConfigurationNamingTheField) {
  const std::pair<const char*, const char*> cases[] = {
      // Regular expressions: the message must start with the field's path.
      {"sensors { id: \"sr\" preset: \"sr3000\" fov_h_deg: -3 }",
       R"(fusiond: sensors\[0\]\.fov_h_deg: )"},
      {"map { fusion_rule: \"average\" }", R"(fusiond: map\.fusion_rule: )"},
      {"ingest { reliability: \"sometimes\" }", R"(fusiond: ingest\.reliability: )"},
      // Once an abort in core ("beam too long for the cell size").
      {"sensors { id: \"sr\" preset: \"sr3000\" r_max_m: 1e9 }",
       R"(fusiond: sensors\[0\]\.r_max_m: )"},
  };
  for (const auto& [text, field] : cases) {
    std::ofstream(config_) << text << "\n";
    // Through a shell: the message goes to stderr.
    Subprocess bad({"/bin/sh", "-c", kFusiond + " --config " + config_ + " 2>&1"});
    EXPECT_TRUE(bad.WaitForOutput(field, 10s)) << text << " gave: " << bad.output();
    EXPECT_EQ(bad.Wait(10s), 2) << text;
  }
}

}  // namespace
