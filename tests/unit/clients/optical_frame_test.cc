// --frame body (ToOpticalFrame): points of a REP-103 body frame turned into the optical frame
// with the pose composed so that the world points stay put, and a scan's --pose rotation
// really applied (world = R p + t).
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <string>
#include <vector>

#include "fusion/clients/importers.h"
#include "import_test_util.h"

namespace fusion::clients::import_test {
namespace {

fusion::v1::RecordedPose MakePose(double tx, double ty, double tz, double qx, double qy, double qz,
                                  double qw) {
  const double n = std::sqrt(qx * qx + qy * qy + qz * qz + qw * qw);
  fusion::v1::RecordedPose pose;
  pose.set_tx(tx);
  pose.set_ty(ty);
  pose.set_tz(tz);
  pose.set_qx(qx / n);
  pose.set_qy(qy / n);
  pose.set_qz(qz / n);
  pose.set_qw(qw / n);
  return pose;
}

std::vector<std::array<float, 3>> Points(const fusion::v1::RecordedCloud& cloud) {
  std::vector<std::array<float, 3>> points(cloud.xyz_f32le().size() / 12);
  for (std::size_t i = 0; i < points.size(); ++i) GetPoint(cloud, i, points[i].data());
  return points;
}

TEST(PointFrameTest, ParsesOpticalAndBodyOnly) {
  PointFrame frame = PointFrame::kOptical;
  ASSERT_TRUE(ParsePointFrame("--frame", "body", &frame).ok());
  EXPECT_EQ(frame, PointFrame::kBody);
  ASSERT_TRUE(ParsePointFrame("--frame", "optical", &frame).ok());
  EXPECT_EQ(frame, PointFrame::kOptical);
  const Status s = ParsePointFrame("--frame", "Body", &frame);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("--frame"), std::string::npos) << s.message();
}

TEST(PointFrameTest, BodyAxesBecomeOpticalAxes) {
  fusion::v1::RecordedCloud cloud;
  *cloud.mutable_t_world_sensor() = MakePose(0, 0, 0, 0, 0, 0, 1);
  AppendPoint(2, 0, 0, &cloud);  // forward
  AppendPoint(0, 3, 0, &cloud);  // left
  AppendPoint(0, 0, 4, &cloud);  // up
  ToOpticalFrame(PointFrame::kBody, &cloud);
  const auto p = Points(cloud);
  EXPECT_EQ(p[0], (std::array<float, 3>{0, 0, 2}));   // forward = +z
  EXPECT_EQ(p[1], (std::array<float, 3>{-3, 0, 0}));  // left = -x
  EXPECT_EQ(p[2], (std::array<float, 3>{0, -4, 0}));  // up = -y
  // The optical frame's pose in a body-aligned world: q = (-0.5, 0.5, -0.5, 0.5) up to sign.
  const auto& q = cloud.t_world_sensor();
  const double sign = q.qw() < 0 ? -1 : 1;
  EXPECT_NEAR(sign * q.qx(), -0.5, 1e-12);
  EXPECT_NEAR(sign * q.qy(), 0.5, 1e-12);
  EXPECT_NEAR(sign * q.qz(), -0.5, 1e-12);
  EXPECT_NEAR(sign * q.qw(), 0.5, 1e-12);
}

TEST(PointFrameTest, WorldPointsStayWhereTheyWereAndOpticalChangesNothing) {
  fusion::v1::RecordedCloud cloud;
  *cloud.mutable_t_world_sensor() = MakePose(1.5, -2, 0.7, 0.1, -0.3, 0.45, 0.8);
  for (int i = 0; i < 20; ++i) {
    AppendPoint(0.3f * i - 2, 1.1f - 0.2f * i, 0.05f * i * i - 1, &cloud);
  }
  const auto body = Points(cloud);
  const fusion::v1::RecordedPose T_world_body = cloud.t_world_sensor();

  fusion::v1::RecordedCloud same = cloud;
  ToOpticalFrame(PointFrame::kOptical, &same);
  EXPECT_EQ(same.SerializeAsString(), cloud.SerializeAsString());

  ToOpticalFrame(PointFrame::kBody, &cloud);
  const auto optical = Points(cloud);
  ASSERT_EQ(optical.size(), body.size());
  for (std::size_t i = 0; i < body.size(); ++i) {
    double before[3], after[3];
    ToWorld(T_world_body, body[i].data(), before);
    ToWorld(cloud.t_world_sensor(), optical[i].data(), after);
    for (int a = 0; a < 3; ++a) EXPECT_NEAR(after[a], before[a], 1e-5) << i << " axis " << a;
  }
  EXPECT_EQ(cloud.t_world_sensor().tx(), 1.5);
}

// --pose's rotation reaches the recorded pose: a scan turned 90 degrees left (about z) and
// moved lands at R p + t, read as optical points or as body points.
TEST(PointFrameTest, ScanPoseRotationIsApplied) {
  const std::string path = TempPath("rotated_scan.txt");
  WriteFile(path, "1 0 0\n0 2 0\n0 0 3\n1.5 -0.5 0.25\n");
  const double s = std::sqrt(0.5);
  const fusion::v1::RecordedPose pose = MakePose(10, 20, 30, 0, 0, s, s);
  // R = Rz(90 deg): (x, y, z) -> (-y, x, z).
  const double expected[4][3] = {{10, 21, 30}, {8, 20, 30}, {10, 20, 33}, {10.5, 21.5, 30.25}};
  for (const PointFrame frame : {PointFrame::kOptical, PointFrame::kBody}) {
    std::vector<fusion::v1::RecordedCloud> clouds;
    const Status st = ReadXyzScan(path, pose, &clouds);
    ASSERT_TRUE(st.ok()) << st.message();
    ASSERT_EQ(clouds.size(), 1u);
    ToOpticalFrame(frame, &clouds[0]);
    const auto points = Points(clouds[0]);
    ASSERT_EQ(points.size(), 4u);
    for (std::size_t i = 0; i < 4; ++i) {
      double world[3];
      ToWorld(clouds[0].t_world_sensor(), points[i].data(), world);
      for (int a = 0; a < 3; ++a) EXPECT_NEAR(world[a], expected[i][a], 1e-5) << i << ", " << a;
    }
  }
  std::remove(path.c_str());
}

// NODE poses are the poses of the points' frame: with body, the OctoMap convention.
TEST(PointFrameTest, NodePosesOfBodyScansKeepTheirWorldPoints) {
  const std::string path = TempPath("node_scan.txt");
  WriteFile(path, "NODE 1 2 3 0 0 1.5707963267948966\n4 0 0\n0 0 1\n");
  fusion::v1::RecordedPose origin;
  origin.set_qw(1.0);
  std::vector<fusion::v1::RecordedCloud> clouds;
  ASSERT_TRUE(ReadXyzScan(path, origin, &clouds).ok());
  ASSERT_EQ(clouds.size(), 1u);
  ToOpticalFrame(PointFrame::kBody, &clouds[0]);
  const auto points = Points(clouds[0]);
  ASSERT_EQ(points.size(), 2u);
  EXPECT_EQ(points[0], (std::array<float, 3>{0, 0, 4}));  // 4 m ahead, on the optical axis
  const double expected[2][3] = {{1, 6, 3}, {1, 2, 4}};   // yaw 90 deg: ahead is world +y
  for (std::size_t i = 0; i < 2; ++i) {
    double world[3];
    ToWorld(clouds[0].t_world_sensor(), points[i].data(), world);
    for (int a = 0; a < 3; ++a) EXPECT_NEAR(world[a], expected[i][a], 1e-5) << i << ", " << a;
  }
  std::remove(path.c_str());
}

}  // namespace
}  // namespace fusion::clients::import_test
