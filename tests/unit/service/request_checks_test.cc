// The request checks (request_checks.h) on text-format requests: the edges of every documented
// range, the status code of each refusal, the QueryBox request as the handler reads it, and
// page tokens that round-trip.
#include "fusion/service/request_checks.h"

#include <gtest/gtest.h>

#include "fusion/service/config.h"
#include "text_proto.h"

namespace fusion::service {
namespace {

using grpc::StatusCode;

using testing::Text;

fusion::v1::QueryLimits Limits() {
  auto limits = DefaultConfig().limits();
  limits.set_max_points_per_query(3);
  limits.set_max_voxels_per_page(50);
  return limits;
}

StatusCode PointsCode(const std::string& text) {
  return CheckQueryPoints(Text<fusion::v1::QueryPointsRequest>(text), Limits()).error_code();
}

TEST(RequestChecksTest, QueryPointsAtMostTheLimitAllFinite) {
  EXPECT_EQ(PointsCode(""), StatusCode::OK);
  EXPECT_EQ(PointsCode("points {} points {} points { x: 1e300 }"), StatusCode::OK);
  EXPECT_EQ(PointsCode("points {} points {} points {} points {}"), StatusCode::RESOURCE_EXHAUSTED);
  EXPECT_EQ(PointsCode("points {} points { z: nan }"), StatusCode::INVALID_ARGUMENT);
  const auto status =
      CheckQueryPoints(Text<fusion::v1::QueryPointsRequest>("points {} points { y: -inf }"),
                       Limits());
  EXPECT_NE(status.error_message().find("points[1]"), std::string::npos) << status.error_message();
}

TEST(RequestChecksTest, QueryBoxReadsTheRequestWithItsDefaults) {
  BoxQuery query;
  ASSERT_TRUE(CheckQueryBox(Text<fusion::v1::QueryBoxRequest>(
                                "min { x: -1 y: -2 z: -3 } max { x: 1 y: 2 z: 3 }"),
                            Limits(), &query)
                  .ok());
  EXPECT_EQ(query.min_m, Eigen::Vector3d(-1, -2, -3));
  EXPECT_EQ(query.max_m, Eigen::Vector3d(1, 2, 3));
  EXPECT_EQ(query.page_size, 50u);  // the limit
  EXPECT_EQ(query.states, (std::set<int>{fusion::v1::VOXEL_STATE_OCCUPIED,
                                         fusion::v1::VOXEL_STATE_FREE}));
  EXPECT_FALSE(query.has_token);

  ASSERT_TRUE(CheckQueryBox(Text<fusion::v1::QueryBoxRequest>(
                                "page_size: 50 states: VOXEL_STATE_UNKNOWN page_token: \"k1.2.3\""),
                            Limits(), &query)
                  .ok());  // a point box (min = max = 0) is a box
  EXPECT_EQ(query.states, std::set<int>{fusion::v1::VOXEL_STATE_UNKNOWN});
  ASSERT_TRUE(query.has_token);
  EXPECT_EQ(query.after, octomap::OcTreeKey(1, 2, 3));
}

TEST(RequestChecksTest, QueryBoxRefusals) {
  const auto code = [](const std::string& text) {
    BoxQuery query;
    return CheckQueryBox(Text<fusion::v1::QueryBoxRequest>(text), Limits(), &query).error_code();
  };
  EXPECT_EQ(code("page_size: 51"), StatusCode::RESOURCE_EXHAUSTED);
  EXPECT_EQ(code("min { y: 0.001 }"), StatusCode::INVALID_ARGUMENT);  // min.y > max.y
  EXPECT_EQ(code("max { z: inf }"), StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(code("states: 3"), StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(code("page_token: \"x\""), StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(code("page_token: \"k1.2.3.\""), StatusCode::INVALID_ARGUMENT);  // trailing bytes
  EXPECT_EQ(code("page_token: \"k65536.0.0\""), StatusCode::INVALID_ARGUMENT);
}

TEST(RequestChecksTest, PageTokensRoundTrip) {
  for (const auto& key : {octomap::OcTreeKey(0, 0, 0), octomap::OcTreeKey(65535, 1, 32768)}) {
    octomap::OcTreeKey decoded;
    ASSERT_TRUE(DecodePageToken(EncodePageToken(key), &decoded));
    EXPECT_EQ(decoded, key);
  }
}

StatusCode RayCode(const std::string& text) {
  return CheckCastRay(Text<fusion::v1::CastRayRequest>(text)).error_code();
}

TEST(RequestChecksTest, CastRayRangeAndDirection) {
  EXPECT_EQ(RayCode("direction { x: 1e-6 } max_range_m: 1000"), StatusCode::OK);
  EXPECT_EQ(RayCode("direction { x: 1e-10 } max_range_m: 1"), StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(RayCode("direction { x: 1 } max_range_m: 1000.001"), StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(RayCode("direction { x: 1 } max_range_m: -1"), StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(RayCode("direction { x: 1 } max_range_m: nan"), StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(RayCode("direction { x: nan } max_range_m: 1"), StatusCode::INVALID_ARGUMENT);
}

StatusCode PlanesCode(const std::string& text) {
  return CheckFindPlanes(Text<fusion::v1::FindPlanesRequest>(text)).error_code();
}

TEST(RequestChecksTest, FindPlanesRanges) {
  EXPECT_EQ(PlanesCode(""), StatusCode::OK);  // every default
  EXPECT_EQ(PlanesCode("max_planes: 64 min_probability: 0.999 angle_step_deg: 0.1 "
                       "distance_step_m: 0.001"),
            StatusCode::OK);
  EXPECT_EQ(PlanesCode("angle_step_deg: 45 distance_step_m: 10"), StatusCode::OK);
  EXPECT_EQ(PlanesCode("region_min { x: -1 } region_max { x: 1 }"), StatusCode::OK);
  EXPECT_EQ(PlanesCode("max_planes: 65"), StatusCode::RESOURCE_EXHAUSTED);
  EXPECT_EQ(PlanesCode("region_max { x: 1 }"), StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(PlanesCode("region_min { x: 1 } region_max { x: 0 }"), StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(PlanesCode("min_probability: 1"), StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(PlanesCode("angle_step_deg: 0.099"), StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(PlanesCode("angle_step_deg: -1"), StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(PlanesCode("angle_step_deg: nan"), StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(PlanesCode("distance_step_m: 0.0009"), StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(PlanesCode("distance_step_m: 10.01"), StatusCode::INVALID_ARGUMENT);
}

TEST(RequestChecksTest, InspectBeamAndGetSnapshot) {
  EXPECT_EQ(CheckInspectBeam(Text<fusion::v1::InspectBeamRequest>("")).error_code(),
            StatusCode::INVALID_ARGUMENT);
  EXPECT_TRUE(CheckInspectBeam(Text<fusion::v1::InspectBeamRequest>("sensor_id: \"a\"")).ok());
  EXPECT_TRUE(CheckGetSnapshot(Text<fusion::v1::GetSnapshotRequest>("format: FORMAT_BT")).ok());
  EXPECT_EQ(CheckGetSnapshot(Text<fusion::v1::GetSnapshotRequest>("format: 2")).error_code(),
            StatusCode::INVALID_ARGUMENT);
}

}  // namespace
}  // namespace fusion::service
