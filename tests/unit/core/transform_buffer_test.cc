#include "fusion/core/transform_buffer.h"

#include <gtest/gtest.h>

#include <cmath>
#include <stdexcept>
#include <string>

namespace fusion {
namespace {

Eigen::Isometry3d Pose(double x, double y, double z, double yaw_rad = 0.0) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.translation() = Eigen::Vector3d(x, y, z);
  T.linear() = Eigen::AngleAxisd(yaw_rad, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  return T;
}

void ExpectNear(const Eigen::Isometry3d& actual, const Eigen::Isometry3d& expected,
                double tolerance = 1e-12) {
  EXPECT_TRUE(actual.isApprox(expected, tolerance)) << "actual\n"
                                                    << actual.matrix() << "\nexpected\n"
                                                    << expected.matrix();
  EXPECT_LT((actual.translation() - expected.translation()).norm(), 1e-9);
}

TEST(TransformBuffer, StatusNames) {
  EXPECT_STREQ(TransformStatusName(TransformStatus::kOk), "ok");
  EXPECT_STREQ(TransformStatusName(TransformStatus::kNoTransform), "no_transform");
  EXPECT_STREQ(TransformStatusName(TransformStatus::kTooOld), "transform_too_old");
  EXPECT_STREQ(TransformStatusName(TransformStatus::kExtrapolation), "extrapolation");
}

TEST(TransformBuffer, RejectsBadOptions) {
  EXPECT_THROW(TransformBuffer(0.0), std::invalid_argument);
  EXPECT_THROW(TransformBuffer(-1.0), std::invalid_argument);
  EXPECT_THROW(TransformBuffer(NAN), std::invalid_argument);
  EXPECT_THROW(TransformBuffer(1.0, 0), std::invalid_argument);
}

TEST(TransformBuffer, UnknownAndDisconnectedFramesHaveNoTransform) {
  TransformBuffer buffer;
  Eigen::Isometry3d T = Pose(7, 7, 7);
  EXPECT_EQ(buffer.Lookup("map", "camera", 1.0, &T), TransformStatus::kNoTransform);
  EXPECT_TRUE(T.isApprox(Pose(7, 7, 7)));  // untouched
  buffer.Add("map", "base", 1.0, Pose(1, 0, 0), false);
  buffer.Add("odom", "robot2", 1.0, Pose(1, 0, 0), false);
  EXPECT_EQ(buffer.Lookup("map", "camera", 1.0, &T), TransformStatus::kNoTransform);
  EXPECT_EQ(buffer.Lookup("camera", "map", 1.0, &T), TransformStatus::kNoTransform);
  EXPECT_EQ(buffer.Lookup("map", "robot2", 1.0, &T), TransformStatus::kNoTransform);
  EXPECT_EQ(buffer.Lookup("base", "odom", 1.0, &T), TransformStatus::kNoTransform);
  // Equal frames are the identity, known or not.
  ASSERT_EQ(buffer.Lookup("camera", "camera", 1.0, &T), TransformStatus::kOk);
  ExpectNear(T, Eigen::Isometry3d::Identity());
}

TEST(TransformBuffer, ChainThroughCommonAncestor) {
  // map -> odom -> base -> camera, and map -> tag: camera in tag's frame goes up to map.
  TransformBuffer buffer;
  const Eigen::Isometry3d T_map_odom = Pose(1, 2, 0, 0.3);
  const Eigen::Isometry3d T_odom_base = Pose(0.5, 0, 0, -1.1);
  const Eigen::Isometry3d T_base_camera = Pose(0.1, 0, 0.4, 0.2);
  const Eigen::Isometry3d T_map_tag = Pose(-3, 1, 2, 2.0);
  buffer.Add("map", "odom", 5.0, T_map_odom, true);
  buffer.Add("odom", "base", 5.0, T_odom_base, false);
  buffer.Add("base", "camera", 0.0, T_base_camera, true);
  buffer.Add("map", "tag", 0.0, T_map_tag, true);

  Eigen::Isometry3d T;
  ASSERT_EQ(buffer.Lookup("map", "camera", 5.0, &T), TransformStatus::kOk);
  ExpectNear(T, T_map_odom * T_odom_base * T_base_camera);
  ASSERT_EQ(buffer.Lookup("camera", "map", 5.0, &T), TransformStatus::kOk);
  ExpectNear(T, (T_map_odom * T_odom_base * T_base_camera).inverse());
  ASSERT_EQ(buffer.Lookup("tag", "camera", 5.0, &T), TransformStatus::kOk);
  ExpectNear(T, T_map_tag.inverse() * T_map_odom * T_odom_base * T_base_camera);
  // The common ancestor below the root: map is not needed for base <- camera.
  ASSERT_EQ(buffer.Lookup("odom", "camera", 5.0, &T), TransformStatus::kOk);
  ExpectNear(T, T_odom_base * T_base_camera);
  // A point in the camera's frame lands where composing by hand puts it.
  ASSERT_EQ(buffer.Lookup("map", "camera", 5.0, &T), TransformStatus::kOk);
  const Eigen::Vector3d p_camera(0, 0, 2);
  const Eigen::Vector3d p_map = T * p_camera;
  EXPECT_LT((p_map - T_map_odom * (T_odom_base * (T_base_camera * p_camera))).norm(), 1e-12);
}

TEST(TransformBuffer, InterpolatesTranslationLinearlyAndRotationBySlerp) {
  TransformBuffer buffer;
  buffer.Add("map", "base", 10.0, Pose(0, 0, 0, 0.0), false);
  buffer.Add("map", "base", 11.0, Pose(2, -4, 1, 1.0), false);
  Eigen::Isometry3d T;
  ASSERT_EQ(buffer.Lookup("map", "base", 10.25, &T), TransformStatus::kOk);
  ExpectNear(T, Pose(0.5, -1, 0.25, 0.25));
  ASSERT_EQ(buffer.Lookup("map", "base", 11.0, &T), TransformStatus::kOk);
  ExpectNear(T, Pose(2, -4, 1, 1.0));
  ASSERT_EQ(buffer.Lookup("map", "base", 10.0, &T), TransformStatus::kOk);
  ExpectNear(T, Pose(0, 0, 0, 0.0));
  // Slerp takes the short way round: from +170 deg to -170 deg passes 180, not 0.
  const double deg = M_PI / 180.0;
  buffer.Add("map", "turn", 0.0, Pose(0, 0, 0, 170 * deg), false);
  buffer.Add("map", "turn", 1.0, Pose(0, 0, 0, -170 * deg), false);
  ASSERT_EQ(buffer.Lookup("map", "turn", 0.5, &T), TransformStatus::kOk);
  ExpectNear(T, Pose(0, 0, 0, 180 * deg), 1e-9);
}

TEST(TransformBuffer, OutOfOrderSamplesAreSortedAndEqualStampsReplace) {
  TransformBuffer buffer;
  buffer.Add("map", "base", 3.0, Pose(3, 0, 0), false);
  buffer.Add("map", "base", 1.0, Pose(1, 0, 0), false);
  buffer.Add("map", "base", 2.0, Pose(9, 0, 0), false);
  buffer.Add("map", "base", 2.0, Pose(2, 0, 0), false);
  Eigen::Isometry3d T;
  for (double t : {1.0, 1.5, 2.0, 2.5, 3.0}) {
    ASSERT_EQ(buffer.Lookup("map", "base", t, &T), TransformStatus::kOk) << t;
    EXPECT_NEAR(T.translation().x(), t, 1e-12) << t;
  }
}

TEST(TransformBuffer, TooOldAndExtrapolation) {
  TransformBuffer buffer;
  buffer.Add("map", "base", 10.0, Pose(0, 0, 0), false);
  buffer.Add("map", "base", 11.0, Pose(1, 0, 0), false);
  buffer.Add("base", "camera", 0.0, Pose(0, 0, 1), true);
  Eigen::Isometry3d T;
  EXPECT_EQ(buffer.Lookup("map", "camera", 9.9, &T), TransformStatus::kTooOld);
  EXPECT_EQ(buffer.Lookup("map", "camera", 11.1, &T), TransformStatus::kExtrapolation);
  EXPECT_EQ(buffer.Lookup("camera", "map", 11.1, &T), TransformStatus::kExtrapolation);
  // Static edges hold at every time.
  ASSERT_EQ(buffer.Lookup("base", "camera", -1e9, &T), TransformStatus::kOk);
  ExpectNear(T, Pose(0, 0, 1));
  // A late transform turns the extrapolation into an interpolation.
  buffer.Add("map", "base", 12.0, Pose(2, 0, 0), false);
  ASSERT_EQ(buffer.Lookup("map", "camera", 11.5, &T), TransformStatus::kOk);
  ExpectNear(T, Pose(1.5, 0, 1));
  // A single dynamic sample holds only at its stamp (and within the stamp tolerance).
  buffer.Add("map", "single", 1.7e9, Pose(1, 1, 1), false);
  EXPECT_EQ(buffer.Lookup("map", "single", 1.7e9, &T), TransformStatus::kOk);
  EXPECT_EQ(buffer.Lookup("map", "single", 1.7e9 + 2.4e-7, &T), TransformStatus::kOk);
  EXPECT_EQ(buffer.Lookup("map", "single", 1.7e9 + 0.01, &T), TransformStatus::kExtrapolation);
  EXPECT_EQ(buffer.Lookup("map", "single", 1.7e9 - 0.01, &T), TransformStatus::kTooOld);
}

TEST(TransformBuffer, HistoryIsBoundedInTimeAndCount) {
  TransformBuffer by_time(2.0, 1000);
  for (int i = 0; i <= 10; ++i) by_time.Add("map", "base", i, Pose(i, 0, 0), false);
  Eigen::Isometry3d T;
  EXPECT_EQ(by_time.Lookup("map", "base", 7.5, &T), TransformStatus::kTooOld);
  EXPECT_EQ(by_time.Lookup("map", "base", 8.0, &T), TransformStatus::kOk);
  // One older than the kept history is dropped at once.
  by_time.Add("map", "base", 1.0, Pose(1, 0, 0), false);
  EXPECT_EQ(by_time.Lookup("map", "base", 1.0, &T), TransformStatus::kTooOld);

  TransformBuffer by_count(100.0, 3);
  for (int i = 0; i < 10; ++i) by_count.Add("map", "base", i, Pose(i, 0, 0), false);
  EXPECT_EQ(by_count.Lookup("map", "base", 6.5, &T), TransformStatus::kTooOld);
  ASSERT_EQ(by_count.Lookup("map", "base", 7.0, &T), TransformStatus::kOk);
  EXPECT_NEAR(T.translation().x(), 7.0, 1e-12);
}

TEST(TransformBuffer, ReparentingAndStaticSwitchStartAFreshEdge) {
  TransformBuffer buffer;
  buffer.Add("map", "camera", 1.0, Pose(1, 0, 0), false);
  buffer.Add("odom", "camera", 2.0, Pose(0, 1, 0), false);
  Eigen::Isometry3d T;
  EXPECT_EQ(buffer.Lookup("map", "camera", 2.0, &T), TransformStatus::kNoTransform);
  ASSERT_EQ(buffer.Lookup("odom", "camera", 2.0, &T), TransformStatus::kOk);
  ExpectNear(T, Pose(0, 1, 0));
  EXPECT_EQ(buffer.Lookup("odom", "camera", 1.0, &T), TransformStatus::kTooOld);
  buffer.Add("odom", "camera", 0.0, Pose(0, 0, 5), true);
  ASSERT_EQ(buffer.Lookup("odom", "camera", 100.0, &T), TransformStatus::kOk);
  ExpectNear(T, Pose(0, 0, 5));
  // A newer static value replaces the old one.
  buffer.Add("odom", "camera", 0.0, Pose(0, 0, 6), true);
  ASSERT_EQ(buffer.Lookup("odom", "camera", 100.0, &T), TransformStatus::kOk);
  ExpectNear(T, Pose(0, 0, 6));
}

TEST(TransformBuffer, IgnoresLoopsAndBadInput) {
  TransformBuffer buffer;
  buffer.Add("a", "b", 0.0, Pose(1, 0, 0), true);
  buffer.Add("b", "c", 0.0, Pose(1, 0, 0), true);
  buffer.Add("c", "a", 0.0, Pose(1, 0, 0), true);  // would close a loop: ignored
  buffer.Add("x", "x", 0.0, Pose(1, 0, 0), true);
  buffer.Add("", "y", 0.0, Pose(1, 0, 0), true);
  buffer.Add("a", "nan_stamp", NAN, Pose(1, 0, 0), false);
  buffer.Add("a", "nan_pose", 0.0, Pose(NAN, 0, 0), false);
  Eigen::Isometry3d T;
  ASSERT_EQ(buffer.Lookup("a", "c", 0.0, &T), TransformStatus::kOk);
  ExpectNear(T, Pose(2, 0, 0));
  EXPECT_EQ(buffer.Lookup("a", "y", 0.0, &T), TransformStatus::kNoTransform);
  EXPECT_EQ(buffer.Lookup("a", "nan_stamp", 0.0, &T), TransformStatus::kNoTransform);
  EXPECT_EQ(buffer.Lookup("a", "nan_pose", 0.0, &T), TransformStatus::kNoTransform);
  EXPECT_EQ(buffer.Lookup("a", "c", NAN, &T), TransformStatus::kNoTransform);
  // A rotation that is a little off unit (float quaternions on the wire) is normalised.
  Eigen::Isometry3d scaled = Pose(0, 0, 0, 0.5);
  scaled.linear() *= 1.0001;
  buffer.Add("a", "scaled", 0.0, scaled, true);
  ASSERT_EQ(buffer.Lookup("a", "scaled", 0.0, &T), TransformStatus::kOk);
  ExpectNear(T, Pose(0, 0, 0, 0.5), 1e-9);
}

}  // namespace
}  // namespace fusion
