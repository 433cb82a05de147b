// The ROS 2 ingest's configuration, its rejection reasons and its conversions from the Cyclone
// samples (the DDS part runs in tests/integration/ros2_ingest_test.cc).
#include <google/protobuf/text_format.h>
#include <gtest/gtest.h>

#include <cmath>
#include <set>
#include <string>

#include "fusion/core/transform_buffer.h"
#include "fusion/ros2/points.h"
#include "fusion/service/config.h"
#include "fusion/service/conversions.h"
#include "fusion/service/ros2_ingest.h"

namespace fusion::service {
namespace {

fusion::v1::ServiceConfig Parse(const std::string& text) {
  fusion::v1::ServiceConfig config = DefaultConfig();
  fusion::v1::ServiceConfig loaded;
  EXPECT_TRUE(google::protobuf::TextFormat::ParseFromString(text, &loaded)) << text;
  config.MergeFrom(loaded);
  return config;
}

// The error of the configuration (empty: valid), from ValidateConfig, which checks ROS 2 too.
std::string Error(const std::string& text) { return ValidateConfig(Parse(text)).message(); }

TEST(Ros2IngestConfig, DefaultsAndFields) {
  const auto options = Ros2IngestOptionsFromConfig(
      Parse("sensors { id: \"sr\" preset: \"sr3000\" ros2_topic: \"rt/sr/points\" }\n"
            "sensors { id: \"cam\" preset: \"kinect_v1\" pinhole { stride: 4 } ros2_topic: "
            "\"rt/camera/depth/image_raw\" ros2_type: \"depth_image\" ros2_reliable: true }\n"
            "sensors { id: \"plain\" preset: \"stoc\" }\n"));
  ASSERT_TRUE(options.ok()) << options.status().message();
  EXPECT_EQ(options->map_frame, "map");
  EXPECT_TRUE(options->tf);
  EXPECT_DOUBLE_EQ(options->tf_wait_s, 0.2);
  EXPECT_DOUBLE_EQ(options->tf_history_s, 10.0);
  ASSERT_EQ(options->sensors.size(), 2u);  // "plain" reads fusion/points
  const Ros2Sensor& sr = options->sensors[0];
  EXPECT_EQ(sr.sensor_id, "sr");
  EXPECT_EQ(sr.topic, "rt/sr/points");
  EXPECT_FALSE(sr.depth_image);
  EXPECT_FALSE(sr.reliable);
  const Ros2Sensor& cam = options->sensors[1];
  EXPECT_TRUE(cam.depth_image);
  EXPECT_TRUE(cam.reliable);
  EXPECT_EQ(cam.camera_info_topic, "rt/camera/depth/camera_info");
  ASSERT_TRUE(cam.pinhole.has_value());
  EXPECT_EQ(cam.pinhole->stride, 4);
  EXPECT_EQ(cam.pinhole->width_px, 640);

  const auto set = Ros2IngestOptionsFromConfig(
      Parse("ros2 { map_frame: \"/odom\" tf: false tf_wait_s: 0 tf_history_s: 30 }"));
  ASSERT_TRUE(set.ok()) << set.status().message();
  EXPECT_EQ(set->map_frame, "odom");  // tf2 drops a leading '/'
  EXPECT_FALSE(set->tf);
  EXPECT_DOUBLE_EQ(set->tf_wait_s, 0.0);
  EXPECT_DOUBLE_EQ(set->tf_history_s, 30.0);
}

// A depth_image sensor without intrinsics (no pinhole block with them, no pinhole preset) is
// valid: its beams wait for its first CameraInfo, at the configured stride; the rest of the
// sensor is checked as always.
TEST(Ros2IngestConfig, DepthImageWithoutIntrinsicsTakesThemFromCameraInfo) {
  const std::string forward_model = "r_min_m: 0.3 r_max_m: 4 q_mu { a1: 1 } q_sigma { a0: 0.01 } ";
  const std::string sensor = "sensors { id: \"cam\" " + forward_model +
                             "pinhole { stride: 4 } ros2_topic: \"rt/cam/depth/image_raw\" "
                             "ros2_type: \"depth_image\" }";
  EXPECT_EQ(Error(sensor), "");
  EXPECT_EQ(Error("sensors { id: \"sr\" preset: \"sr3000\" ros2_topic: \"rt/d\" ros2_type: "
                  "\"depth_image\" }"),
            "");  // sr3000's forward model, the CameraInfo's pixels
  EXPECT_NE(Error("sensors { id: \"cam\" r_min_m: 0.3 r_max_m: 4 q_sigma { a0: 0.01 } "
                  "ros2_topic: \"rt/d\" ros2_type: \"depth_image\" }")
                .find("sensors[0].q_mu: required"),
            std::string::npos);
  EXPECT_NE(Error("sensors { id: \"cam\" r_min_m: 5 r_max_m: 4 q_mu { a1: 1 } q_sigma { a0: "
                  "0.01 } ros2_topic: \"rt/d\" ros2_type: \"depth_image\" }")
                .find("sensors[0].r_max_m: "),
            std::string::npos);
  // The stride awaiting a CameraInfo is bounded as a configured pinhole's is.
  EXPECT_NE(Error("sensors { id: \"cam\" " + forward_model +
                  "pinhole { stride: 70000 } ros2_topic: \"rt/d\" ros2_type: \"depth_image\" }")
                .find("sensors[0].pinhole: width, height and stride must be at most 65536"),
            std::string::npos);
  // Without ros2_type depth_image the same sensor still needs its geometry.
  EXPECT_NE(Error("sensors { id: \"cam\" " + forward_model + "}").find("sensors[0].fov_h_deg: "),
            std::string::npos);

  const auto setup = SensorSetupFromConfig(Parse(sensor).sensors(0));
  ASSERT_TRUE(setup.ok()) << setup.status().message();
  EXPECT_TRUE(setup->intrinsics_from_camera_info);
  EXPECT_EQ(setup->camera_stride, 4);
  EXPECT_FALSE(setup->spec.pinhole.has_value());
  EXPECT_EQ(setup->spec.cols * setup->spec.rows, 0);
  const auto options = Ros2IngestOptionsFromConfig(Parse(sensor));
  ASSERT_TRUE(options.ok()) << options.status().message();
  EXPECT_FALSE(options->sensors[0].pinhole.has_value());

  ros2::CameraInfo info;
  info.width = 80;
  info.height = 60;
  info.k = {60.0, 0.0, 39.5, 0.0, 61.0, 29.5, 0.0, 0.0, 1.0};
  const auto spec = SpecFromCameraInfo(*setup, info);
  ASSERT_TRUE(spec.ok()) << spec.status().message();
  ASSERT_TRUE(spec->pinhole.has_value());
  EXPECT_DOUBLE_EQ(spec->pinhole->fx_px, 60.0);
  EXPECT_DOUBLE_EQ(spec->pinhole->fy_px, 61.0);
  EXPECT_DOUBLE_EQ(spec->pinhole->cx_px, 39.5);
  EXPECT_DOUBLE_EQ(spec->pinhole->cy_px, 29.5);
  EXPECT_EQ(spec->pinhole->stride, 4);
  EXPECT_EQ(spec->cols, 20);  // ceil(80 / 4)
  EXPECT_EQ(spec->rows, 15);
  EXPECT_DOUBLE_EQ(spec->r_max_m, 4.0);
  // A CameraInfo that makes no camera is refused, by the pinhole block's rules.
  ros2::CameraInfo zero;
  EXPECT_NE(SpecFromCameraInfo(*setup, zero).status().message().find("CameraInfo: "),
            std::string::npos);
  ros2::CameraInfo huge = info;
  huge.width = 100000;
  EXPECT_NE(SpecFromCameraInfo(*setup, huge).status().message().find("at most 65536"),
            std::string::npos);
  ros2::CameraInfo no_focal = info;
  no_focal.k[0] = 0.0;
  EXPECT_NE(SpecFromCameraInfo(*setup, no_focal).status().message().find("focal lengths"),
            std::string::npos);
}

TEST(Ros2IngestConfig, CameraInfoTopicIsTheImagesSibling) {
  EXPECT_EQ(DefaultCameraInfoTopic("rt/camera/depth/image_raw"), "rt/camera/depth/camera_info");
  EXPECT_EQ(DefaultCameraInfoTopic("rt/depth"), "rt/camera_info");
  EXPECT_EQ(DefaultCameraInfoTopic("depth"), "camera_info");
}

TEST(Ros2IngestConfig, BadFieldsAreNamed) {
  EXPECT_EQ(Error(""), "");
  EXPECT_NE(Error("sensors { id: \"a\" preset: \"sr3000\" ros2_type: \"point_cloud2\" }")
                .find("sensors[0].ros2_topic: "),
            std::string::npos);
  EXPECT_NE(Error("sensors { id: \"a\" preset: \"sr3000\" ros2_topic: \"/points\" }")
                .find("sensors[0].ros2_topic: '/points' is a ROS 2 name; its DDS topic is "
                      "'rt/points'"),
            std::string::npos);
  EXPECT_NE(Error("sensors { id: \"a\" preset: \"sr3000\" ros2_topic: \"rt/p\" ros2_type: \"x\" }")
                .find("sensors[0].ros2_type: 'x' is not point_cloud2 or depth_image"),
            std::string::npos);
  // A depth image's beams are its pixels: angular fields do not apply to one.
  EXPECT_NE(Error("sensors { id: \"a\" preset: \"sr3000\" fov_h_deg: 40 fov_v_deg: 30 cols: 4 "
                  "rows: 3 ros2_topic: \"rt/d\" ros2_type: \"depth_image\" }")
                .find("sensors[0].pinhole: a depth image's beams are its pixels"),
            std::string::npos);
  EXPECT_NE(Error("sensors { id: \"a\" preset: \"sr3000\" ros2_topic: \"rt/p\" "
                  "ros2_camera_info_topic: \"rt/c\" }")
                .find("sensors[0].ros2_camera_info_topic: only for ros2_type depth_image"),
            std::string::npos);
  EXPECT_NE(Error("sensors { id: \"a\" preset: \"sr3000\" ros2_topic: \"rt/p\" }\n"
                  "sensors { id: \"b\" preset: \"sr3000\" ros2_topic: \"rt/p\" }")
                .find("sensors[1].ros2_topic: 'rt/p' is taken"),
            std::string::npos);
  EXPECT_NE(
      Error("sensors { id: \"a\" preset: \"sr3000\" ros2_topic: \"rt/tf\" }").find("is taken"),
      std::string::npos);
  EXPECT_NE(Error("ros2 { tf_wait_s: 11 }").find("ros2.tf_wait_s: "), std::string::npos);
  EXPECT_NE(Error("ros2 { tf_wait_s: -1 }").find("ros2.tf_wait_s: "), std::string::npos);
  EXPECT_NE(Error("ros2 { tf_history_s: -1 }").find("ros2.tf_history_s: "), std::string::npos);
  EXPECT_NE(Error("ros2 { tf_history_s: 4000 }").find("ros2.tf_history_s: "), std::string::npos);
}

// The service's reasons carry the converter's and the transform buffer's names, so that the
// live ingest and the bag importer count the same words.
TEST(Ros2IngestConfig, ReasonNamesAreTheConvertersAndTheTransformBuffers) {
  const std::pair<RejectReason, ros2::Ros2Reject> converter[] = {
      {RejectReason::kRos2FieldsMissing, ros2::Ros2Reject::kFieldsMissing},
      {RejectReason::kRos2FieldType, ros2::Ros2Reject::kFieldType},
      {RejectReason::kRos2PointStep, ros2::Ros2Reject::kPointStep},
      {RejectReason::kRos2DataShort, ros2::Ros2Reject::kDataShort},
      {RejectReason::kRos2TooLarge, ros2::Ros2Reject::kTooLarge},
      {RejectReason::kRos2Encoding, ros2::Ros2Reject::kEncoding},
      {RejectReason::kRos2CameraInfo, ros2::Ros2Reject::kCameraInfo},
  };
  for (const auto& [ours, theirs] : converter) {
    EXPECT_STREQ(RejectReasonName(ours), ros2::Ros2RejectName(theirs));
  }
  const std::pair<RejectReason, TransformStatus> tf[] = {
      {RejectReason::kNoTransform, TransformStatus::kNoTransform},
      {RejectReason::kTransformTooOld, TransformStatus::kTooOld},
      {RejectReason::kExtrapolation, TransformStatus::kExtrapolation},
  };
  for (const auto& [ours, theirs] : tf)
    EXPECT_STREQ(RejectReasonName(ours), TransformStatusName(theirs));
  EXPECT_STREQ(RejectReasonName(RejectReason::kCameraInfoMismatch), "camera_info_mismatch");
}

TEST(Ros2IngestConversions, SamplesBecomeMessagesThatPointIntoThem) {
  sensor_msgs_msg_dds__PointField_ fields[2] = {{const_cast<char*>("x"), 0, 7, 1},
                                                {const_cast<char*>("y"), 4, 7, 1}};
  std::uint8_t bytes[8] = {1, 2, 3, 4, 5, 6, 7, 8};
  sensor_msgs_msg_dds__PointCloud2_ sample{};
  sample.header.stamp = {12, 500'000'000};
  sample.header.frame_id = const_cast<char*>("/camera");
  sample.height = 1;
  sample.width = 1;
  sample.fields._buffer = fields;
  sample.fields._length = 2;
  sample.point_step = 8;
  sample.row_step = 8;
  sample.data._buffer = bytes;
  sample.data._length = 8;
  const ros2::PointCloud2 msg = Ros2FromDds(sample);
  EXPECT_DOUBLE_EQ(msg.header.stamp.seconds(), 12.5);
  EXPECT_EQ(Ros2FrameId(msg.header.frame_id), "camera");
  ASSERT_EQ(msg.fields.size(), 2u);
  EXPECT_EQ(msg.fields[1].name, "y");
  EXPECT_EQ(msg.fields[1].offset, 4u);
  EXPECT_EQ(msg.data.data, bytes);  // a view, no copy
  EXPECT_EQ(msg.data.size, 8u);

  // Null strings and sequences (a sample Cyclone filled sparsely) become empty ones.
  sensor_msgs_msg_dds__Image_ image{};
  const ros2::Image empty = Ros2FromDds(image);
  EXPECT_TRUE(empty.encoding.empty());
  EXPECT_TRUE(empty.data.empty());
}

TEST(Ros2IngestConversions, TransformsAndCloudsInTheSensorFrame) {
  ros2::Transform t;
  t.translation = {1, 2, 3};
  t.rotation = {0, 0, std::sin(0.25), std::cos(0.25)};  // 0.5 rad about z
  const Eigen::Isometry3d T = IsometryFromRos2(t);
  EXPECT_TRUE(T.translation().isApprox(Eigen::Vector3d(1, 2, 3)));
  EXPECT_NEAR(std::atan2(T(1, 0), T(0, 0)), 0.5, 1e-12);
  ros2::Transform zero;
  zero.rotation = {0, 0, 0, 0};
  EXPECT_FALSE(IsometryFromRos2(zero).matrix().allFinite());

  // With a mount T_frame_sensor, the points move from the message's frame into the sensor's.
  Eigen::Isometry3d T_frame_sensor = Eigen::Isometry3d::Identity();
  T_frame_sensor.translation() = Eigen::Vector3d(0, 0, 1);
  const Eigen::Isometry3d T_sensor_frame = T_frame_sensor.inverse();
  const float nan = std::nanf("");
  const Cloud cloud = CloudFromRos2("s", 7, 3.5, Eigen::Isometry3d::Identity(), &T_sensor_frame, 2,
                                    1, {1, 2, 3, nan, nan, nan});
  EXPECT_EQ(cloud.sensor_id, "s");
  EXPECT_EQ(cloud.sequence_number, 7u);
  EXPECT_DOUBLE_EQ(cloud.stamp_s, 3.5);
  ASSERT_EQ(cloud.xyz.size(), 6u);
  EXPECT_FLOAT_EQ(cloud.xyz[2], 2.0f);
  EXPECT_TRUE(std::isnan(cloud.xyz[3]));
  // The same rules as a fusion::dds::PointCloud: a non-finite pose is refused.
  Cloud bad = cloud;
  bad.T_world_published.translation().x() = NAN;
  std::string detail;
  const auto reason = ValidateCloud(
      bad, IngestLimits{}, [](const std::string&) { return true; }, &detail);
  ASSERT_TRUE(reason.has_value());
  EXPECT_EQ(*reason, RejectReason::kNonFinitePose);
  EXPECT_FALSE(ValidateCloud(
                   cloud, IngestLimits{}, [](const std::string&) { return true; }, &detail)
                   .has_value())
      << detail;
}

}  // namespace
}  // namespace fusion::service
