// ROS 2 ingest end to end: a Fast DDS participant (ROS 2's default middleware) publishes
// sensor_msgs/PointCloud2, depth sensor_msgs/Image + CameraInfo and tf2_msgs/TFMessage on rt/
// topics with ROS 2's type names, XCDR1 and QoS, and fusiond (Cyclone DDS) maps them: the
// simulated board occupied where it stands, the space in front of it free, every message counted
// in ListSensors. tf: a static mount published before fusiond starts (transient local), a cloud
// whose transform comes 100 ms late (interpolated), clouds without a transform; bad messages
// rejected with their reason while fusiond keeps running.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <chrono>
#include <fstream>
#include <functional>
#include <iterator>
#include <regex>
#include <string>
#include <thread>
#include <vector>

#include "../support/e2e_service.h"

#ifdef FUSION_HAVE_FASTDDS
#include <octomap/AbstractOcTree.h>
#include <octomap/OcTree.h>

#include <cstring>
#include <filesystem>
#include <map>
#include <memory>
#include <sstream>
#include <tuple>

#include "../support/fastdds_ros2.h"
#include "../support/ros2_board_messages.h"
#include "../unit/ros2/bag_scene.h"
#endif

namespace {

using fusion::testing::E2eService;
using namespace std::chrono_literals;
namespace v1 = fusion::v1;

#ifndef FUSION_HAVE_FASTDDS
TEST(Ros2IngestTest, NeedsFastDds) {
  GTEST_SKIP() << "Fast DDS (libfastrtps-dev, fastddsgen) absent";
}
#else

using fusion::testing::FastDdsRos2;
using fusion::testing::Ros2Qos;
using namespace fusion::testing::ros2_board;

class Ros2IngestTest : public E2eService {
 protected:
  // fusiond with `config`, its log (info: the ros2 reader's match lines) in the test's folder.
  void Start(const std::string& config) {
    const std::string path = dir_ + "/fusiond.pbtxt";
    log_path_ = dir_ + "/fusiond.log";
    std::ofstream(path) << config;
    fusiond_ = std::make_unique<fusion::testing::Subprocess>(std::vector<std::string>{
        "/bin/sh", "-c",
        "exec '" + fusion::testing::kBuildDir + "/service/fusiond' --config '" + path +
            "' --listen 127.0.0.1:0 --dds-domain " + std::to_string(domain_) + " 2>>'" + log_path_ +
            "'"});
    ASSERT_TRUE(fusiond_->started());
    const auto port = fusiond_->WaitForOutput(R"(fusiond listening on 127\.0\.0\.1:(\d+))", 20s);
    ASSERT_TRUE(port) << "no 'listening' line: " << Log();
    address_ = "127.0.0.1:" + *port;
    stub_ =
        v1::FusionMap::NewStub(grpc::CreateChannel(address_, grpc::InsecureChannelCredentials()));
  }
  std::string Log() const {
    std::ifstream in(log_path_);
    return std::string(std::istreambuf_iterator<char>(in), {});
  }
  // Waits until fusiond's reader on `topic` matched a writer: a volatile reader drops what a
  // writer sent before the reader knew it, even when the writer saw the match first. Cyclone's
  // volatile reader also starts at the sequence number of the writer's first heartbeat after
  // the match (Fast DDS sends one every 20 ms here, fastdds_ros2.h): a sample written before
  // that heartbeat is acknowledged but not delivered, hence the pause after the match.
  bool WaitForMatch(const std::string& topic, std::chrono::seconds timeout = 10s) {
    const std::regex matched("ros2: [1-9][0-9]* writer\\(s\\) matched on '" + topic + "'");
    const auto end = std::chrono::steady_clock::now() + timeout;
    while (std::chrono::steady_clock::now() < end) {
      if (std::regex_search(Log(), matched)) {
        std::this_thread::sleep_for(200ms);
        return true;
      }
      std::this_thread::sleep_for(10ms);
    }
    ADD_FAILURE() << "fusiond's reader on " << topic << " matched no writer: " << Log();
    return false;
  }

  static std::string BaseConfig() {
    return "log_level: \"info\"\n"
           "map { resolution_m: 0.05 render_interval_ms: 100 }\n"
           "ingest { max_points: 100000 }\n";
  }
  static std::string SrSensor(const std::string& topic) {
    return "sensors { id: \"sr\" preset: \"sr3000\" cols: " + std::to_string(kCols) +
           " rows: " + std::to_string(kRows) + " ros2_topic: \"" + topic +
           "\" ros2_reliable: true }\n";
  }

  // Waits until `done` holds for the sensor's counters (bounded).
  bool WaitCounters(const std::string& id,
                    const std::function<bool(const v1::SensorCounters&)>& done,
                    std::chrono::seconds timeout = 10s) {
    const auto end = std::chrono::steady_clock::now() + timeout;
    while (std::chrono::steady_clock::now() < end) {
      if (done(Counters(id))) return true;
      std::this_thread::sleep_for(20ms);
    }
    return false;
  }
  static std::uint64_t Reason(const v1::SensorCounters& c, const std::string& reason) {
    const auto it = c.rejected_by_reason().find(reason);
    return it == c.rejected_by_reason().end() ? 0 : it->second;
  }

  void ExpectBoardMapped() {
    const auto r = Query({kOnBoard, kInFront});
    ASSERT_EQ(r.size(), 2u);
    EXPECT_EQ(r[0].state(), v1::VOXEL_STATE_OCCUPIED) << "board, p = " << r[0].probability();
    EXPECT_EQ(r[1].state(), v1::VOXEL_STATE_FREE) << "in front, p = " << r[1].probability();
  }

  std::string log_path_;
};

// PointCloud2 posed by tf: map -> base on rt/tf, base -> sr_optical on rt/tf_static published
// before fusiond started (transient local: it still arrives).
TEST_F(Ros2IngestTest, PointCloud2MapsTheBoardWithAStaticMountPublishedBeforeFusiond) {
  FastDdsRos2 dds(domain_);
  ASSERT_TRUE(dds.ok());
  auto* tf_static =
      dds.Writer<tf2_msgs::msg::dds_::TFMessage_PubSubType>("rt/tf_static", Ros2Qos::kTfStatic);
  ASSERT_NE(tf_static, nullptr);
  TfMessage mount = Tf("base", "sr_optical", 0.0, OpticalAxes());
  ASSERT_TRUE(FastDdsRos2::Publish(tf_static, mount));

  Start(BaseConfig() + SrSensor("rt/sr/points"));
  auto* tf = dds.Writer<tf2_msgs::msg::dds_::TFMessage_PubSubType>("rt/tf", Ros2Qos::kTf);
  auto* points = dds.Writer<sm::PointCloud2_PubSubType>("rt/sr/points", Ros2Qos::kReliable);
  ASSERT_TRUE(FastDdsRos2::WaitForReader(points, 10s)) << "fusiond's reader did not match";
  ASSERT_TRUE(FastDdsRos2::WaitForReader(tf, 10s));
  ASSERT_TRUE(WaitForMatch("rt/sr/points") && WaitForMatch("rt/tf") &&
              WaitForMatch("rt/tf_static"));

  constexpr int kClouds = 8;
  for (int k = 0; k < kClouds; ++k) {
    const double stamp_s = 100.0 + 0.1 * k;
    TfMessage odom = Tf("map", "base", stamp_s, Eigen::Isometry3d::Identity());
    ASSERT_TRUE(FastDdsRos2::Publish(tf, odom));
    auto cloud = BoardCloud(k + 1, "sr_optical", stamp_s);
    ASSERT_TRUE(FastDdsRos2::Publish(points, cloud));
  }
  ASSERT_TRUE(WaitInMap(kClouds, 20s)) << "clouds in map: " << Stats().clouds_in_map() << Log();
  const auto c = Counters("sr");
  EXPECT_EQ(c.received(), kClouds);
  EXPECT_EQ(c.rejected(), 0u);
  EXPECT_EQ(c.integrated(), kClouds);
  ExpectBoardMapped();
}

// Each cloud's stamp lies half-way between two transforms (base at x = -0.4 and +0.4 m); the
// later one comes 100 ms after the cloud. Interpolated, the board lands at x = 1.75; at either
// neighbour it would land 0.4 m off.
TEST_F(Ros2IngestTest, LateTransformIsWaitedForAndInterpolated) {
  Start(BaseConfig() + SrSensor("rt/sr/points") + "ros2 { tf_wait_s: 0.5 }\n");
  FastDdsRos2 dds(domain_);
  ASSERT_TRUE(dds.ok());
  auto* tf_static =
      dds.Writer<tf2_msgs::msg::dds_::TFMessage_PubSubType>("rt/tf_static", Ros2Qos::kTfStatic);
  auto* tf = dds.Writer<tf2_msgs::msg::dds_::TFMessage_PubSubType>("rt/tf", Ros2Qos::kTf);
  auto* points = dds.Writer<sm::PointCloud2_PubSubType>("rt/sr/points", Ros2Qos::kReliable);
  ASSERT_TRUE(FastDdsRos2::WaitForReader(points, 10s));
  ASSERT_TRUE(FastDdsRos2::WaitForReader(tf, 10s));
  ASSERT_TRUE(FastDdsRos2::WaitForReader(tf_static, 10s));
  ASSERT_TRUE(WaitForMatch("rt/sr/points") && WaitForMatch("rt/tf") &&
              WaitForMatch("rt/tf_static"));
  TfMessage mount = Tf("base", "sr_optical", 0.0, OpticalAxes());
  ASSERT_TRUE(FastDdsRos2::Publish(tf_static, mount));

  constexpr int kClouds = 8;
  const auto base_at = [](int k) { return Translation(k % 2 == 0 ? -0.4 : 0.4, 0, 0); };
  TfMessage first = Tf("map", "base", 200.0, base_at(0));
  ASSERT_TRUE(FastDdsRos2::Publish(tf, first));
  for (int k = 0; k < kClouds; ++k) {
    auto cloud = BoardCloud(k + 1, "sr_optical", 200.0 + 0.1 * k + 0.05);
    ASSERT_TRUE(FastDdsRos2::Publish(points, cloud));
    std::this_thread::sleep_for(100ms);
    TfMessage next = Tf("map", "base", 200.0 + 0.1 * (k + 1), base_at(k + 1));
    ASSERT_TRUE(FastDdsRos2::Publish(tf, next));
  }
  ASSERT_TRUE(WaitInMap(kClouds, 20s)) << "clouds in map: " << Stats().clouds_in_map()
                                       << ", rejected: " << Counters("sr").rejected();
  const auto c = Counters("sr");
  EXPECT_EQ(c.received(), kClouds);
  EXPECT_EQ(c.rejected(), 0u);
  ExpectBoardMapped();
  const auto off = Query({kTooNear, kTooFar});
  EXPECT_NE(off[0].state(), v1::VOXEL_STATE_OCCUPIED) << "a cloud posed at x = -0.4";
  EXPECT_NE(off[1].state(), v1::VOXEL_STATE_OCCUPIED) << "a cloud posed at x = +0.4";
}

// Depth images without tf (ros2.tf false: the mount is the pose), with sensor-data QoS as a
// ROS 2 camera driver publishes them: one camera sends 16UC1, the other 32FC1, each with a
// CameraInfo that agrees with its configured intrinsics.
TEST_F(Ros2IngestTest, DepthImagesMapTheBoard) {
  const std::string depth_sensor = " r_min_m: 0.3 r_max_m: 4 q_mu { a1: 1 } q_sigma { a0: 0.01 } " +
                                   PinholeBlock() + " " + MountBlock(OpticalAxes()) +
                                   " ros2_type: \"depth_image\" }\n";
  Start(BaseConfig() + "ros2 { tf: false }\n" +
        "sensors { id: \"mm\" ros2_topic: \"rt/mm/depth/image_raw\"" + depth_sensor +
        "sensors { id: \"m\" ros2_topic: \"rt/m/depth/image_raw\"" + depth_sensor);
  FastDdsRos2 dds(domain_);
  ASSERT_TRUE(dds.ok());
  const std::vector<std::pair<std::string, std::string> > cameras = {{"mm", "16UC1"},
                                                                     {"m", "32FC1"}};
  std::vector<fusion::testing::fdds::DataWriter*> infos, images;
  for (const auto& [id, encoding] : cameras) {
    infos.push_back(dds.Writer<sm::CameraInfo_PubSubType>("rt/" + id + "/depth/camera_info",
                                                          Ros2Qos::kSensorData));
    images.push_back(
        dds.Writer<sm::Image_PubSubType>("rt/" + id + "/depth/image_raw", Ros2Qos::kSensorData));
    ASSERT_TRUE(FastDdsRos2::WaitForReader(infos.back(), 10s)) << id;
    ASSERT_TRUE(FastDdsRos2::WaitForReader(images.back(), 10s)) << id;
  }
  // Best effort: a message sent before fusiond's reader knows the writer is lost, so publish
  // until each camera has a few in (bounded).
  constexpr std::uint64_t kImages = 5;
  std::uint64_t published = 0;
  const auto end = std::chrono::steady_clock::now() + 20s;
  while (std::chrono::steady_clock::now() < end &&
         (Counters("mm").received() < kImages || Counters("m").received() < kImages)) {
    for (std::size_t i = 0; i < cameras.size(); ++i) {
      auto camera_info = CameraInfo("camera_optical", kFocalPx);
      ASSERT_TRUE(FastDdsRos2::Publish(infos[i], camera_info));
      auto depth = BoardDepthImage(cameras[i].second, "camera_optical", 50.0 + 0.1 * published);
      ASSERT_TRUE(FastDdsRos2::Publish(images[i], depth));
    }
    ++published;
    std::this_thread::sleep_for(50ms);
  }
  std::uint64_t received = 0;
  for (const auto& [id, encoding] : cameras) {
    const auto c = Counters(id);
    EXPECT_GE(c.received(), kImages) << id;
    EXPECT_LE(c.received(), published) << id;
    EXPECT_EQ(c.rejected(), 0u) << id << ": " << c.DebugString();
    received += c.received();
  }
  ASSERT_TRUE(WaitInMap(received, 20s)) << "clouds in map: " << Stats().clouds_in_map();
  for (const auto& [id, encoding] : cameras) EXPECT_GT(Counters(id).points_updated(), 0u) << id;
  ExpectBoardMapped();
}

// A depth camera configured without intrinsics: its beams are its first CameraInfo's pixels
// (at the configured stride 2: 40 x 30 beams). An image before any CameraInfo is rejected as
// no_camera_info; images after it map the board; a CameraInfo that disagrees later is refused
// as with configured intrinsics.
TEST_F(Ros2IngestTest, DepthImagesTakeTheirIntrinsicsFromTheFirstCameraInfo) {
  Start(BaseConfig() + "ros2 { tf: false }\n" +
        "sensors { id: \"auto\" r_min_m: 0.3 r_max_m: 4 q_mu { a1: 1 } q_sigma { a0: 0.01 } "
        "pinhole { stride: 2 } " +
        MountBlock(OpticalAxes()) +
        " ros2_topic: \"rt/auto/depth/image_raw\" ros2_type: \"depth_image\""
        " ros2_reliable: true }\n");
  const auto beams = [&] {
    grpc::ClientContext context;
    SetDeadline(&context, 5s);
    v1::ListSensorsResponse reply;
    EXPECT_TRUE(stub_->ListSensors(&context, v1::ListSensorsRequest(), &reply).ok());
    return reply.sensors_size() == 1 ? reply.sensors(0) : v1::SensorInfo();
  };
  EXPECT_EQ(beams().beams(), 0u) << "no beams before a CameraInfo";
  FastDdsRos2 dds(domain_);
  ASSERT_TRUE(dds.ok());
  auto* info =
      dds.Writer<sm::CameraInfo_PubSubType>("rt/auto/depth/camera_info", Ros2Qos::kReliable);
  auto* image = dds.Writer<sm::Image_PubSubType>("rt/auto/depth/image_raw", Ros2Qos::kReliable);
  for (auto* w : {info, image}) ASSERT_TRUE(FastDdsRos2::WaitForReader(w, 10s));
  ASSERT_TRUE(WaitForMatch("rt/auto/depth/camera_info") && WaitForMatch("rt/auto/depth/image_raw"));
  // GetStats counts the ROS 2 readers' writers with the points topic's (none here).
  EXPECT_EQ(Stats().matched_writers(), 2u);
  EXPECT_GE(Stats().matched_writers_total(), 2u);

  auto early = BoardDepthImage("16UC1", "auto_optical", 1.0);
  ASSERT_TRUE(FastDdsRos2::Publish(image, early));
  ASSERT_TRUE(WaitCounters("auto", [](const auto& c) { return c.rejected() == 1; }))
      << Counters("auto").DebugString();
  EXPECT_EQ(Reason(Counters("auto"), "no_camera_info"), 1u);

  auto camera_info = CameraInfo("auto_optical", kFocalPx);
  ASSERT_TRUE(FastDdsRos2::Publish(info, camera_info));
  // The CameraInfo and the images come on two topics: wait for the beams before the images.
  const auto end = std::chrono::steady_clock::now() + 10s;
  while (beams().beams() == 0 && std::chrono::steady_clock::now() < end) {
    std::this_thread::sleep_for(10ms);
  }
  const v1::SensorInfo sensor = beams();
  EXPECT_EQ(sensor.cols(), kImageWidth / 2);
  EXPECT_EQ(sensor.rows(), kImageHeight / 2);
  constexpr std::uint64_t kImages = 4;
  for (std::uint64_t k = 0; k < kImages; ++k) {
    auto depth = BoardDepthImage("16UC1", "auto_optical", 2.0 + 0.1 * k);
    ASSERT_TRUE(FastDdsRos2::Publish(image, depth));
  }
  ASSERT_TRUE(WaitInMap(kImages, 20s)) << "clouds in map: " << Stats().clouds_in_map() << "\n"
                                       << Counters("auto").DebugString() << Log();
  auto c = Counters("auto");
  EXPECT_EQ(c.received(), kImages + 1);
  EXPECT_EQ(c.integrated(), kImages);
  EXPECT_EQ(c.rejected(), 1u);
  EXPECT_GT(c.points_updated(), 0u);
  ExpectBoardMapped();
  EXPECT_NE(Log().find("intrinsics from its CameraInfo: fx 60 fy 60 cx 39.5 cy 29.5 px, 80 x 60 "
                       "pixels, stride 2: 40 x 30 beams"),
            std::string::npos)
      << Log();

  // A later CameraInfo that disagrees: the images are refused until one agrees again.
  auto other = CameraInfo("auto_optical", 2 * kFocalPx);
  ASSERT_TRUE(FastDdsRos2::Publish(info, other));
  const std::regex refused("CameraInfo K .* disagrees");
  const auto log_end = std::chrono::steady_clock::now() + 10s;
  while (!std::regex_search(Log(), refused) && std::chrono::steady_clock::now() < log_end) {
    std::this_thread::sleep_for(10ms);
  }
  auto after = BoardDepthImage("16UC1", "auto_optical", 3.0);
  ASSERT_TRUE(FastDdsRos2::Publish(image, after));
  EXPECT_TRUE(WaitCounters("auto", [](const auto& c) { return c.rejected() == 2; }))
      << Counters("auto").DebugString();
  c = Counters("auto");
  EXPECT_EQ(Reason(c, "camera_info_mismatch"), 1u);
  EXPECT_EQ(Reason(c, "no_camera_info"), 1u);
  EXPECT_EQ(beams().beams(), static_cast<std::uint32_t>(kImageWidth / 2 * kImageHeight / 2));
}

// A full-size Kinect depth image (640 x 480 16UC1, 600 kB: many DDS fragments) with the
// kinect_v1 preset's intrinsics at a stride of 8, before any CameraInfo came.
TEST_F(Ros2IngestTest, FullSizeDepthImagesArriveInFragments) {
  Start(BaseConfig() + "ros2 { tf: false }\n" +
        "sensors { id: \"kinect\" preset: \"kinect_v1\" pinhole { stride: 8 } " +
        MountBlock(OpticalAxes()) +
        " ros2_topic: \"rt/kinect/depth/image_raw\" ros2_type: \"depth_image\""
        " ros2_reliable: true }\n");
  FastDdsRos2 dds(domain_);
  ASSERT_TRUE(dds.ok());
  auto* image = dds.Writer<sm::Image_PubSubType>("rt/kinect/depth/image_raw", Ros2Qos::kReliable);
  ASSERT_TRUE(FastDdsRos2::WaitForReader(image, 10s));
  ASSERT_TRUE(WaitForMatch("rt/kinect/depth/image_raw"));
  // A volatile Cyclone reader starts at the writer's first heartbeat: a first sample still in
  // fragments when it comes is acknowledged and skipped. A small first message (rejected:
  // "warmup" is no depth encoding) gets the reader in step.
  std::uint64_t warmups = 0;
  const auto warm_end = std::chrono::steady_clock::now() + 10s;
  while ((warmups = Counters("kinect").rejected()) == 0 &&
         std::chrono::steady_clock::now() < warm_end) {
    auto warmup = BoardDepthImage("16UC1", "kinect_optical", 1.0, 1, 1);
    warmup.encoding("warmup");
    ASSERT_TRUE(FastDdsRos2::Publish(image, warmup));
    std::this_thread::sleep_for(50ms);
  }
  ASSERT_GT(warmups, 0u);
  constexpr int kImages = 3;
  for (int k = 0; k < kImages; ++k) {
    auto depth = BoardDepthImage("16UC1", "kinect_optical", 10.0 + k, 640, 480);
    ASSERT_TRUE(FastDdsRos2::Publish(image, depth));
  }
  ASSERT_TRUE(WaitInMap(kImages, 20s)) << "clouds in map: " << Stats().clouds_in_map() << "\n"
                                       << Counters("kinect").DebugString() << Log();
  const auto c = Counters("kinect");
  EXPECT_EQ(c.received(), kImages + c.rejected());
  EXPECT_EQ(c.rejected(), Reason(c, "encoding"));  // only the warm-ups
  ExpectBoardMapped();
}

// Bad point clouds are rejected with a counted reason; fusiond keeps running and maps what is
// good.
TEST_F(Ros2IngestTest, BadPointCloudsAreRejectedWithTheirReason) {
  Start(BaseConfig() + SrSensor("rt/sr/points") + "ros2 { tf_wait_s: 0.3 }\n");
  FastDdsRos2 dds(domain_);
  ASSERT_TRUE(dds.ok());
  auto* tf_static =
      dds.Writer<tf2_msgs::msg::dds_::TFMessage_PubSubType>("rt/tf_static", Ros2Qos::kTfStatic);
  auto* tf = dds.Writer<tf2_msgs::msg::dds_::TFMessage_PubSubType>("rt/tf", Ros2Qos::kTf);
  auto* points = dds.Writer<sm::PointCloud2_PubSubType>("rt/sr/points", Ros2Qos::kReliable);
  for (auto* w : {tf_static, tf, points}) ASSERT_TRUE(FastDdsRos2::WaitForReader(w, 10s));
  ASSERT_TRUE(WaitForMatch("rt/sr/points") && WaitForMatch("rt/tf") &&
              WaitForMatch("rt/tf_static"));
  TfMessage mount = Tf("base", "sr_optical", 0.0, OpticalAxes());
  ASSERT_TRUE(FastDdsRos2::Publish(tf_static, mount));
  for (double stamp_s : {300.0, 300.1}) {
    TfMessage odom = Tf("map", "base", stamp_s, Eigen::Isometry3d::Identity());
    ASSERT_TRUE(FastDdsRos2::Publish(tf, odom));
  }

  const auto good = [] { return BoardCloud(1, "sr_optical", 300.05); };
  auto first = good();
  ASSERT_TRUE(FastDdsRos2::Publish(points, first));
  std::vector<std::pair<std::string, sm::PointCloud2_> > bad;
  auto m = good();
  m.fields().erase(m.fields().begin() + 2);  // no z
  bad.emplace_back("fields_missing", m);
  m = good();
  m.fields()[0].datatype(8);  // FLOAT64 x
  bad.emplace_back("field_type", m);
  m = good();
  m.point_step(8);  // z (offset 8) beyond the point
  m.row_step(8 * m.width());
  bad.emplace_back("point_step", m);
  m = good();
  m.data().resize(m.data().size() - 16);  // shorter than row_step * height
  bad.emplace_back("data_short", m);
  m = good();
  m.width(100000);  // 1e10 points in a few kB
  m.height(100000);
  bad.emplace_back("too_large", m);
  bad.emplace_back("no_transform", BoardCloud(1, "nowhere", 300.05));
  bad.emplace_back("transform_too_old", BoardCloud(1, "sr_optical", 100.0));
  bad.emplace_back("extrapolation", BoardCloud(1, "sr_optical", 310.0));
  for (auto& [reason, cloud] : bad) ASSERT_TRUE(FastDdsRos2::Publish(points, cloud)) << reason;
  auto last = good();
  ASSERT_TRUE(FastDdsRos2::Publish(points, last));

  const std::uint64_t kBad = bad.size();
  EXPECT_TRUE(WaitCounters("sr", [&](const auto& c) {
    return c.received() == kBad + 2 && c.rejected() == kBad;
  })) << Counters("sr").DebugString();
  const auto sr = Counters("sr");
  for (const auto& [reason, cloud] : bad) EXPECT_EQ(Reason(sr, reason), 1u) << reason;
  // Still serving: the good clouds are in the map, the totals count the reasons too.
  ASSERT_TRUE(WaitInMap(2, 20s)) << "clouds in map: " << Stats().clouds_in_map();
  EXPECT_EQ(Stats().rejected_by_reason().at("no_transform"), 1u);
}

// Bad depth images (a CameraInfo that disagrees with the configured intrinsics, an encoding
// that is not depth, another size) are rejected with their reason; a good one after them maps.
TEST_F(Ros2IngestTest, BadDepthImagesAreRejectedWithTheirReason) {
  Start(BaseConfig() +
        "sensors { id: \"depth\" r_min_m: 0.3 r_max_m: 4 q_mu { a1: 1 } q_sigma { a0: 0.01 } " +
        PinholeBlock() +
        " ros2_topic: \"rt/cam/depth/image_raw\" ros2_type: \"depth_image\""
        " ros2_reliable: true }\n");
  FastDdsRos2 dds(domain_);
  ASSERT_TRUE(dds.ok());
  auto* tf_static =
      dds.Writer<tf2_msgs::msg::dds_::TFMessage_PubSubType>("rt/tf_static", Ros2Qos::kTfStatic);
  auto* info =
      dds.Writer<sm::CameraInfo_PubSubType>("rt/cam/depth/camera_info", Ros2Qos::kReliable);
  auto* image = dds.Writer<sm::Image_PubSubType>("rt/cam/depth/image_raw", Ros2Qos::kReliable);
  for (auto* w : {tf_static, info, image}) ASSERT_TRUE(FastDdsRos2::WaitForReader(w, 10s));
  for (const char* topic : {"rt/tf_static", "rt/cam/depth/camera_info", "rt/cam/depth/image_raw"}) {
    ASSERT_TRUE(WaitForMatch(topic));
  }
  TfMessage mount = Tf("map", "cam_optical", 0.0, OpticalAxes());
  ASSERT_TRUE(FastDdsRos2::Publish(tf_static, mount));

  auto wrong_info = CameraInfo("cam_optical", 2 * kFocalPx);
  ASSERT_TRUE(FastDdsRos2::Publish(info, wrong_info));
  auto disagreeing = BoardDepthImage("16UC1", "cam_optical", 1.0);
  ASSERT_TRUE(FastDdsRos2::Publish(image, disagreeing));
  auto right_info = CameraInfo("cam_optical", kFocalPx);
  ASSERT_TRUE(FastDdsRos2::Publish(info, right_info));
  auto rgb = BoardDepthImage("16UC1", "cam_optical", 1.1);
  rgb.encoding("rgb8");
  ASSERT_TRUE(FastDdsRos2::Publish(image, rgb));
  auto small = BoardDepthImage("32FC1", "cam_optical", 1.2);
  small.width(kImageWidth / 2);  // the data still holds the full rows: only the size is wrong
  ASSERT_TRUE(FastDdsRos2::Publish(image, small));
  auto depth = BoardDepthImage("32FC1", "cam_optical", 1.3);
  ASSERT_TRUE(FastDdsRos2::Publish(image, depth));

  EXPECT_TRUE(WaitCounters("depth", [](const auto& c) {
    return c.received() == 4 && c.rejected() == 3;
  })) << Counters("depth").DebugString();
  const auto c = Counters("depth");
  EXPECT_EQ(Reason(c, "camera_info_mismatch"), 1u);
  EXPECT_EQ(Reason(c, "encoding"), 1u);
  EXPECT_EQ(Reason(c, "camera_info"), 1u);
  ASSERT_TRUE(WaitInMap(1, 20s)) << "clouds in map: " << Stats().clouds_in_map();
  ExpectBoardMapped();
}

// The bag that the rosbag2 tests write (tests/unit/ros2/bag_scene.h: a robot driving past a
// board, tf on /tf and /tf_static, an organized 8 x 6 PointCloud2 in its optical frame) mapped
// three ways by fresh fusionds with the sensors { ... } block fusion-import prints: live, its
// messages' CDR bytes published by Fast DDS on rt/ topics as a ROS 2 node would (all tf first,
// so that every cloud finds the same transforms as the importer, which reads the whole bag);
// and imported from the .db3 and from the MCAP bag with fusion-import rosbag2, replayed with
// fusion-replay. Reliable ingest (no cloud merged while the renderer is behind) makes the map
// independent of timing: the three hold the same occupied voxels with the same values.
class Rosbag2ReplayTest : public Ros2IngestTest {
 protected:
  using Leaves = std::map<std::tuple<std::uint16_t, std::uint16_t, std::uint16_t, unsigned>, float>;

  // The occupied leaves of the map fusiond serves (key, depth -> log-odds).
  Leaves OccupiedLeaves() {
    grpc::ClientContext context;
    SetDeadline(&context, 10s);
    v1::GetSnapshotRequest request;
    request.set_format(v1::GetSnapshotRequest::FORMAT_OT);
    auto reader = stub_->GetSnapshot(&context, request);
    std::string data;
    v1::SnapshotChunk chunk;
    while (reader->Read(&chunk)) data += chunk.data();
    EXPECT_TRUE(reader->Finish().ok());
    std::istringstream in(data);
    std::unique_ptr<octomap::AbstractOcTree> tree(octomap::AbstractOcTree::read(in));
    const auto* octree = dynamic_cast<const octomap::OcTree*>(tree.get());
    Leaves leaves;
    if (octree == nullptr) {
      ADD_FAILURE() << "no OcTree in the snapshot (" << data.size() << " bytes)";
      return leaves;
    }
    for (auto it = octree->begin_leafs(), end = octree->end_leafs(); it != end; ++it) {
      if (!octree->isNodeOccupied(*it)) continue;
      const octomap::OcTreeKey k = it.getKey();
      leaves[{k[0], k[1], k[2], it.getDepth()}] = it->getLogOdds();
    }
    return leaves;
  }

  // fusion-import rosbag2 of the lidar topic; returns the sensors { ... } block it prints.
  std::string Import(const std::string& bag, const std::string& recording) {
    std::string out;
    EXPECT_EQ(fusion::testing::RunTool(
                  {"fusion-import", "rosbag2", bag, "--points-topic", fusion::test::kPointsTopic,
                   "--sensor-id", "lidar", "--print-sensor", "-o", recording},
                  &out),
              0)
        << out;
    return out;
  }

  // A fresh fusiond with the printed sensor (plus the noise model the importer asks for), read
  // from rt/lidar/points too.
  void StartWith(const std::string& sensor_block) {
    const auto close = sensor_block.rfind('}');
    ASSERT_NE(close, std::string::npos) << sensor_block;
    Start(
        "log_level: \"info\"\n"
        "map { resolution_m: 0.05 render_interval_ms: 100 }\n"
        "ingest { max_points: 100000 reliability: \"reliable\" }\n" +
        sensor_block.substr(0, close) +
        " q_mu { a1: 1 } q_sigma { a0: 0.01 } ros2_topic: \"rt/lidar/points\""
        " ros2_reliable: true }\n");
  }

  Leaves Replay(const std::string& recording, const std::string& sensor_block) {
    StartWith(sensor_block);
    std::string out;
    EXPECT_EQ(
        fusion::testing::RunTool({"fusion-replay", recording, "--domain", std::to_string(domain_),
                                  "--fast", "--reliable", "--wait-readers", "1", "--quiet"},
                                 &out),
        0)
        << out;
    EXPECT_TRUE(WaitInMap(kPosedClouds, 20s)) << "clouds in map: " << Stats().clouds_in_map();
    return OccupiedLeaves();
  }

  // The bag's messages on `topic` as Fast DDS samples (the CDR bytes deserialised).
  template <class PubSubType, class Message>
  static std::vector<Message> Samples(const std::vector<fusion::test::BagEvent>& events,
                                      const std::string& topic) {
    std::vector<Message> out;
    PubSubType type;
    for (const auto& e : events) {
      if (e.topic != topic) continue;
      eprosima::fastrtps::rtps::SerializedPayload_t payload(
          static_cast<std::uint32_t>(e.data.size()));
      std::memcpy(payload.data, e.data.data(), e.data.size());
      payload.length = static_cast<std::uint32_t>(e.data.size());
      Message m;
      EXPECT_TRUE(type.deserialize(&payload, &m)) << topic;
      out.push_back(std::move(m));
    }
    return out;
  }

  Leaves Live(const std::vector<fusion::test::BagEvent>& events, const std::string& sensor_block) {
    StartWith(sensor_block);
    FastDdsRos2 dds(domain_);
    EXPECT_TRUE(dds.ok());
    using TfType = tf2_msgs::msg::dds_::TFMessage_PubSubType;
    auto* tf_static = dds.Writer<TfType>("rt/tf_static", Ros2Qos::kTfStatic);
    auto* tf = dds.Writer<TfType>("rt/tf", Ros2Qos::kTf);
    auto* points = dds.Writer<sm::PointCloud2_PubSubType>("rt/lidar/points", Ros2Qos::kReliable);
    for (auto* w : {tf_static, tf, points}) EXPECT_TRUE(FastDdsRos2::WaitForReader(w, 10s));
    EXPECT_TRUE(WaitForMatch("rt/lidar/points") && WaitForMatch("rt/tf") &&
                WaitForMatch("rt/tf_static"));
    for (auto& m : Samples<TfType, TfMessage>(events, "/tf_static")) {
      EXPECT_TRUE(FastDdsRos2::Publish(tf_static, m));
    }
    for (auto& m : Samples<TfType, TfMessage>(events, "/tf")) {
      EXPECT_TRUE(FastDdsRos2::Publish(tf, m));
    }
    for (auto& m : Samples<sm::PointCloud2_PubSubType, sm::PointCloud2_>(
             events, fusion::test::kPointsTopic)) {
      EXPECT_TRUE(FastDdsRos2::Publish(points, m));
    }
    // The last cloud is stamped after the last transform: rejected as extrapolation (the
    // importer skips it for the same reason).
    EXPECT_TRUE(WaitCounters("lidar", [](const auto& c) {
      return c.received() == kPosedClouds + 1 && c.rejected() == 1;
    })) << Counters("lidar").DebugString();
    EXPECT_EQ(Reason(Counters("lidar"), "extrapolation"), 1u);
    EXPECT_TRUE(WaitInMap(kPosedClouds, 20s)) << "clouds in map: " << Stats().clouds_in_map();
    return OccupiedLeaves();
  }

  static constexpr std::uint64_t kPosedClouds = 6;  // bag_scene.h's kCloudTimes
};

TEST_F(Rosbag2ReplayTest, ImportedBagsReplayToTheMapOfTheLiveMessages) {
  const auto events = fusion::test::SceneEvents();
  const std::string db3 = dir_ + "/bag_db3";
  std::filesystem::create_directories(db3);
  fusion::test::WriteSqliteBag(db3, events);
  const std::string mcap = dir_ + "/scene.mcap";
  std::ofstream(mcap, std::ios::binary) << fusion::test::SceneMcap(events);
  const std::string sensor = Import(db3, dir_ + "/db3.frec");
  ASSERT_NE(sensor.find("sensors {"), std::string::npos) << sensor;
  EXPECT_EQ(Import(mcap, dir_ + "/mcap.frec"), sensor) << "the two bags describe one sensor";

  const Leaves live = Live(events, sensor);
  ASSERT_GT(live.size(), 20u) << "the board is not in the live map";
  RecordProperty("occupied_leaves", static_cast<int>(live.size()));
  const Leaves from_db3 = Replay(dir_ + "/db3.frec", sensor);
  const Leaves from_mcap = Replay(dir_ + "/mcap.frec", sensor);
  EXPECT_EQ(from_db3.size(), live.size());
  EXPECT_TRUE(from_db3 == live) << "the .db3 bag's map differs from the live one";
  EXPECT_TRUE(from_mcap == live) << "the MCAP bag's map differs from the live one";
}

#endif  // FUSION_HAVE_FASTDDS

}  // namespace
