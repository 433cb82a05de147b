// QueryPoints, QueryBox and CastRay handlers over an in-process channel (handler_fixture.h):
// answers against the wall scene, and every bad argument answered with its status code.
#include <set>
#include <tuple>

#include "handler_fixture.h"

namespace fusion::service::testing {
namespace {

using grpc::StatusCode;

TEST_F(HandlerTest, QueryPointsAnswersEachPointInOrder) {
  SeeWall(3);
  v1::QueryPointsResponse reply;
  const auto status = QueryPoints("points { " + PointText(kOnWall) + " } points { " +
                                      PointText(kInFront) + " } points { " + PointText(kBehind) +
                                      " }",
                                  &reply);
  ASSERT_TRUE(status.ok()) << status.error_message();
  ASSERT_EQ(reply.results_size(), 3);
  EXPECT_EQ(reply.results(0).state(), v1::VOXEL_STATE_OCCUPIED);
  EXPECT_GT(reply.results(0).probability(), 0.5);
  EXPECT_EQ(reply.results(1).state(), v1::VOXEL_STATE_FREE);
  EXPECT_LT(reply.results(1).probability(), 0.5);
  EXPECT_EQ(reply.results(2).state(), v1::VOXEL_STATE_UNKNOWN);
  EXPECT_EQ(reply.results(2).probability(), 0.5);
  EXPECT_EQ(reply.map_version(), Stats().map_version());
}

TEST_F(HandlerTest, QueryPointsRefusesBadPointsAndTooMany) {
  v1::QueryPointsResponse reply;
  EXPECT_EQ(QueryPoints("points { x: 0 y: nan z: 1 }", &reply).error_code(),
            StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(QueryPoints("points { x: inf y: 0 z: 1 }", &reply).error_code(),
            StatusCode::INVALID_ARGUMENT);
  std::string many;
  for (int i = 0; i <= 100; ++i) many += "points { x: 0 y: 0 z: 1 } ";  // the limit is 100
  const auto status = QueryPoints(many, &reply);
  EXPECT_EQ(status.error_code(), StatusCode::RESOURCE_EXHAUSTED);
  EXPECT_NE(status.error_message().find("limits.max_points_per_query"), std::string::npos);
  ASSERT_TRUE(QueryPoints("", &reply).ok());
  EXPECT_EQ(reply.results_size(), 0);
}

// Every voxel of a box, page by page, as keys (x, y, z) in units of the resolution.
std::set<std::tuple<long, long, long>> Keys(const v1::QueryBoxResponse& reply) {
  std::set<std::tuple<long, long, long>> keys;
  for (const auto& v : reply.voxels()) {
    keys.emplace(std::lround(v.center().x() / kResolutionM - 0.5),
                 std::lround(v.center().y() / kResolutionM - 0.5),
                 std::lround(v.center().z() / kResolutionM - 0.5));
  }
  return keys;
}

TEST_F(HandlerTest, QueryBoxReturnsTheVoxelsInsideInPagesThatChainWithoutOverlap) {
  SeeWall(3);
  const std::string box = "min { x: -0.3 y: -0.3 z: 1.5 } max { x: 0.3 y: 0.3 z: 2.3 } ";
  v1::QueryBoxResponse all;
  ASSERT_TRUE(QueryBox(box + "page_size: 1000", &all).ok());
  ASSERT_TRUE(all.next_page_token().empty());
  ASSERT_GT(all.voxels_size(), 50);
  bool occupied = false, free = false;
  for (const auto& v : all.voxels()) {
    EXPECT_NE(v.state(), v1::VOXEL_STATE_UNKNOWN);  // the default: occupied and free
    occupied |= v.state() == v1::VOXEL_STATE_OCCUPIED;
    free |= v.state() == v1::VOXEL_STATE_FREE;
    for (const double c : {v.center().x(), v.center().y()}) {
      EXPECT_GE(c + v.size_m() / 2, -0.3);
      EXPECT_LE(c - v.size_m() / 2, 0.3);
    }
    EXPECT_GE(v.center().z() + v.size_m() / 2, 1.5);
    EXPECT_LE(v.center().z() - v.size_m() / 2, 2.3);
  }
  EXPECT_TRUE(occupied && free);

  std::set<std::tuple<long, long, long>> paged;
  std::string token;
  int pages = 0;
  do {
    v1::QueryBoxResponse page;
    ASSERT_TRUE(QueryBox(box + "page_size: 7 page_token: \"" + token + "\"", &page).ok());
    ASSERT_LE(page.voxels_size(), 7);
    for (const auto& key : Keys(page)) EXPECT_TRUE(paged.insert(key).second) << "twice";
    token = page.next_page_token();
    ASSERT_LT(++pages, 10000);
  } while (!token.empty());
  EXPECT_EQ(paged, Keys(all));

  v1::QueryBoxResponse occupied_only;
  ASSERT_TRUE(QueryBox(box + "states: VOXEL_STATE_OCCUPIED", &occupied_only).ok());
  ASSERT_GT(occupied_only.voxels_size(), 0);
  for (const auto& v : occupied_only.voxels()) EXPECT_EQ(v.state(), v1::VOXEL_STATE_OCCUPIED);
}

TEST_F(HandlerTest, QueryBoxWalksUnknownVoxelsKeyByKey) {
  SeeWall(1);
  v1::QueryBoxResponse reply;  // behind the sensor: never seen, 4 x 4 x 4 voxels
  ASSERT_TRUE(QueryBox("min { x: 0.01 y: 0.01 z: -0.99 } max { x: 0.19 y: 0.19 z: -0.81 } "
                       "states: VOXEL_STATE_UNKNOWN",
                       &reply)
                  .ok());
  EXPECT_EQ(reply.voxels_size(), 64);
  for (const auto& v : reply.voxels()) EXPECT_EQ(v.state(), v1::VOXEL_STATE_UNKNOWN);
}

TEST_F(HandlerTest, QueryBoxRefusesBadBoxesPagesAndTokens) {
  v1::QueryBoxResponse reply;
  const auto code = [&](const std::string& text) { return QueryBox(text, &reply).error_code(); };
  EXPECT_EQ(code("min { x: nan } max { x: 1 y: 1 z: 1 }"), StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(code("min { x: 2 } max { x: 1 y: 1 z: 1 }"), StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(code("max { x: 1 y: 1 z: 1 } page_size: 1001"), StatusCode::RESOURCE_EXHAUSTED);
  EXPECT_EQ(code("max { x: 1 y: 1 z: 1 } page_token: \"k1.2\""), StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(code("max { x: 1 y: 1 z: 1 } page_token: \"k1.2.99999\""),
            StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(code("max { x: 1 y: 1 z: 1 } states: 7"), StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(code("max { x: 5000 y: 1 z: 1 }"), StatusCode::INVALID_ARGUMENT);  // beyond the keys
  // The default limits.max_box_voxels is far below a 100 m cube at 5 cm (8e9 voxels).
  EXPECT_EQ(code("min { x: -50 y: -50 z: -50 } max { x: 50 y: 50 z: 50 }"),
            StatusCode::RESOURCE_EXHAUSTED);
  EXPECT_TRUE(QueryBox("max { x: 1 y: 1 z: 1 }", &reply).ok());
}

TEST_F(HandlerTest, QueryBoxChecksItsDeadlineWhileWalking) {
  TearDown();
  StartService("limits { max_voxels_per_page: 50000 }");
  // A page of 50 000 unknown voxels (the configured page size) with a deadline too short to
  // build it: the server checks the deadline while walking (the client would give up too).
  const std::string box = "min { } max { x: 4.95 y: 4.95 z: 3.95 } states: VOXEL_STATE_UNKNOWN ";
  v1::QueryBoxResponse reply;
  EXPECT_EQ(Unary(&v1::FusionMap::Stub::QueryBox, Text<v1::QueryBoxRequest>(box), &reply, 2ms)
                .error_code(),
            StatusCode::DEADLINE_EXCEEDED);
  // The same box in pages of 1000 answers in time.
  ASSERT_TRUE(QueryBox(box + "page_size: 1000", &reply).ok());
  EXPECT_EQ(reply.voxels_size(), 1000);
  EXPECT_FALSE(reply.next_page_token().empty());
}

TEST_F(HandlerTest, CastRayStopsAtTheWall) {
  SeeWall(3);
  v1::CastRayResponse reply;
  // From inside the seen free space (the sensor's first few cm lie within its r_min, unknown).
  ASSERT_TRUE(CastRay("origin { x: 0.025 y: 0.025 z: 0.6 } direction { z: 3 } max_range_m: 5",
                      &reply)
                  .ok());
  EXPECT_TRUE(reply.hit());
  EXPECT_EQ(reply.stopped_at(), v1::VOXEL_STATE_OCCUPIED);
  EXPECT_NEAR(reply.end().z(), kWallZ, 2 * kResolutionM);
  EXPECT_NEAR(reply.range_m(), kWallZ - 0.6, 2 * kResolutionM);
  // Too short to reach it: no hit.
  ASSERT_TRUE(CastRay("origin { x: 0.025 y: 0.025 z: 0.6 } direction { z: 1 } max_range_m: 0.5",
                      &reply)
                  .ok());
  EXPECT_FALSE(reply.hit());
  // Away from it, into space never seen: stops at the first unknown voxel, no hit.
  ASSERT_TRUE(CastRay("origin { x: 0.025 y: 0.025 z: 0.6 } direction { z: -1 } max_range_m: 5",
                      &reply)
                  .ok());
  EXPECT_FALSE(reply.hit());
  EXPECT_GT(reply.range_m(), 0.0);
  EXPECT_LT(reply.range_m(), 0.7);
}

TEST_F(HandlerTest, CastRayRefusesBadRays) {
  v1::CastRayResponse reply;
  const auto code = [&](const std::string& text) { return CastRay(text, &reply).error_code(); };
  EXPECT_EQ(code("direction { z: 1 } max_range_m: 0"), StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(code("direction { z: 1 } max_range_m: 1001"), StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(code("direction { } max_range_m: 1"), StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(code("origin { x: nan } direction { z: 1 } max_range_m: 1"),
            StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(code("origin { x: 1600 } direction { x: 1 } max_range_m: 1000"),
            StatusCode::INVALID_ARGUMENT);  // leaves the key range (+-1638 m at 5 cm)
}

}  // namespace
}  // namespace fusion::service::testing
