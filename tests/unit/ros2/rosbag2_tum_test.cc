// The real TUM RGB-D sample (../shared/data, skipped when absent) as a ROS 2 bag: its depth
// frames as 32FC1 Images with the fr2 CameraInfo, its ground truth as tf (world -> the optical
// frame, one transform per frame, recorded after the image). `fusion-import rosbag2` must give
// what `fusion-import tum` gives: the same poses and, to float rounding, the same points.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "../../support/mcap_writer.h"
#include "fusion/clients/importers.h"
#include "fusion/clients/rosbag2.h"
#include "fusion/ros2/cdr.h"

namespace fusion::clients {
namespace {

namespace fs = std::filesystem;
using fusion::v1::RecordedCloud;

const std::string kTum = std::string(FUSION_SHARED_DATA_DIR) + "/tum_fr2_pioneer_slam2";

struct Frame {
  std::string file;
  ros2::Time stamp;
  double pose[7];  // tx ty tz qx qy qz qw: the optical frame in the world
};

std::vector<Frame> ReadGroundTruth() {
  std::vector<Frame> frames;
  std::ifstream in(kTum + "/groundtruth.txt");
  for (std::string line; std::getline(in, line);) {
    if (line.empty() || line[0] == '#') continue;
    Frame f;
    std::istringstream fields(line);
    fields >> f.file;
    for (double& p : f.pose) fields >> p;
    const std::string stamp = fs::path(f.file).stem().string();  // "1311877813.991479"
    const auto dot = stamp.find('.');
    f.stamp.sec = std::stoi(stamp.substr(0, dot));
    f.stamp.nanosec =
        static_cast<std::uint32_t>(std::stoul((stamp.substr(dot + 1) + "000000000").substr(0, 9)));
    frames.push_back(f);
  }
  return frames;
}

std::string TumBag(const std::vector<Frame>& frames) {
  test::McapWriter writer;
  const auto image = writer.AddChannel(writer.AddSchema("sensor_msgs/msg/Image"), "/depth");
  const auto info_channel =
      writer.AddChannel(writer.AddSchema("sensor_msgs/msg/CameraInfo"), "/depth/camera_info");
  const auto tf_channel = writer.AddChannel(writer.AddSchema("tf2_msgs/msg/TFMessage"), "/tf");
  for (const Frame& f : frames) {
    std::uint32_t width = 0, height = 0;
    std::vector<std::uint16_t> raw;
    if (!ReadPng16(kTum + "/" + f.file, &width, &height, &raw).ok()) return "";
    std::vector<std::uint8_t> data(4 * raw.size());
    for (std::size_t i = 0; i < raw.size(); ++i) {
      const float z_m = static_cast<float>(raw[i] / 5000.0);  // 0 stays 0: no return
      std::memcpy(&data[4 * i], &z_m, 4);
    }
    ros2::Image m;
    m.header = {f.stamp, "kinect_optical"};
    m.width = width, m.height = height, m.encoding = "32FC1", m.step = 4 * width;
    m.data = ros2::ByteView(data);
    ros2::CameraInfo info;
    info.header = m.header;
    info.width = width, info.height = height;
    info.k = {520.9, 0, 325.1, 0, 521.0, 249.7, 0, 0, 1};
    ros2::TFMessage tf;
    tf.transforms.resize(1);
    tf.transforms[0].header = {f.stamp, "world"};
    tf.transforms[0].child_frame_id = "kinect_optical";
    tf.transforms[0].transform.translation = {f.pose[0], f.pose[1], f.pose[2]};
    tf.transforms[0].transform.rotation = {f.pose[3], f.pose[4], f.pose[5], f.pose[6]};
    const std::uint64_t t_ns = std::uint64_t(f.stamp.sec) * 1000000000 + f.stamp.nanosec;
    writer.BeginChunk("lz4");
    writer.AddMessage(info_channel, t_ns, ros2::EncodeCdr(info));
    writer.AddMessage(image, t_ns + 1, ros2::EncodeCdr(m, ros2::CdrEndian::kBig));
    writer.AddMessage(tf_channel, t_ns + 2, ros2::EncodeCdr(tf));  // after the image
    writer.EndChunk();
  }
  return writer.Finish();
}

TEST(Rosbag2TumTest, RealDepthFramesGiveWhatTheTumImporterGives) {
  if (!fs::exists(kTum + "/groundtruth.txt")) {
    GTEST_SKIP() << "TUM sample not found at " << kTum << " (see ../shared/data/README.md)";
  }
  const std::vector<Frame> frames = ReadGroundTruth();
  ASSERT_EQ(frames.size(), 10u);
  const std::string bag = TumBag(frames);
  ASSERT_FALSE(bag.empty());
  const std::string path =
      ::testing::TempDir() + "/rosbag2_tum_" + std::to_string(getpid()) + ".mcap";
  std::ofstream(path, std::ios::binary) << bag;

  constexpr int kStride = 4;
  TumOptions tum;
  tum.directory = kTum;
  tum.stride = kStride;
  std::vector<RecordedCloud> expected, got;
  ASSERT_TRUE(ImportTum(tum, [&](RecordedCloud&& c) {
                expected.push_back(std::move(c));
                return Status::Ok();
              }).ok());
  Rosbag2Options o;
  o.bag = path;
  o.depth_topic = "/depth";
  o.camera_info_topic = "/depth/camera_info";
  o.stride = kStride;
  o.map_frame = "world";
  const Status s = ImportRosbag2(o, [&](RecordedCloud&& c) {
    got.push_back(std::move(c));
    return Status::Ok();
  });
  fs::remove(path);
  ASSERT_TRUE(s.ok()) << s.message();
  ASSERT_EQ(got.size(), expected.size());
  for (std::size_t k = 0; k < got.size(); ++k) {
    const RecordedCloud &a = expected[k], &b = got[k];
    EXPECT_EQ(a.stamp().sec(), b.stamp().sec());
    EXPECT_EQ(a.stamp().nanosec(), b.stamp().nanosec());
    ASSERT_EQ(a.width(), b.width());
    ASSERT_EQ(a.height(), b.height());
    const auto& p = a.t_world_sensor();
    const auto& q = b.t_world_sensor();
    EXPECT_NEAR(p.tx(), q.tx(), 1e-9);
    EXPECT_NEAR(p.ty(), q.ty(), 1e-9);
    EXPECT_NEAR(p.tz(), q.tz(), 1e-9);
    const double dot = p.qx() * q.qx() + p.qy() * q.qy() + p.qz() * q.qz() + p.qw() * q.qw();
    EXPECT_NEAR(std::abs(dot), 1.0, 1e-9) << "frame " << k;
    ASSERT_EQ(a.xyz_f32le().size(), b.xyz_f32le().size());
    std::size_t returns = 0;
    for (std::size_t i = 0; i < a.xyz_f32le().size() / 12; ++i) {
      float pa[3], pb[3];
      GetPoint(a, i, pa);
      GetPoint(b, i, pb);
      ASSERT_EQ(std::isnan(pa[2]), std::isnan(pb[2])) << "frame " << k << " point " << i;
      if (std::isnan(pa[2])) continue;
      ++returns;
      for (int c = 0; c < 3; ++c)
        ASSERT_NEAR(pa[c], pb[c], 1e-5) << "frame " << k << " point " << i;
    }
    EXPECT_GT(returns, a.xyz_f32le().size() / 12 / 2) << "frame " << k;
  }
}

}  // namespace
}  // namespace fusion::clients
