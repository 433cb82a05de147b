// fusion-import rosbag2 (fusion/clients/rosbag2.h) on bags the test writes with the published
// schemas (bag_scene.h): sqlite3 and MCAP give the same clouds, posed by the bag's tf
// (interpolated, static mounts, transforms recorded after the cloud); depth images with their
// CameraInfo; missing topics and unknown storage are clear errors; a cut or damaged bag keeps
// the clouds before the break and says where it breaks.
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>

#include "bag_scene.h"
#include "fusion/clients/recording.h"
#include "fusion/clients/rosbag2.h"

namespace fusion::clients {
namespace {

namespace fs = std::filesystem;
using fusion::v1::RecordedCloud;
using ::testing::HasSubstr;

// Every directory made, removed when the suite ends.
std::vector<std::string>& TempDirs() {
  static std::vector<std::string> dirs;
  return dirs;
}

std::string TempDir(const std::string& name) {
  const std::string dir =
      ::testing::TempDir() + "/rosbag2_" + std::to_string(getpid()) + "_" + name;
  fs::remove_all(dir);
  fs::create_directories(dir);
  TempDirs().push_back(dir);
  return dir;
}

void WriteBytes(const std::string& path, const std::string& bytes) {
  std::ofstream(path, std::ios::binary | std::ios::trunc) << bytes;
}

struct Imported {
  Status status;
  std::vector<RecordedCloud> clouds;
  Rosbag2Report report;
};

Imported Import(Rosbag2Options o) {
  Imported out;
  out.status = ImportRosbag2(
      o,
      [&](RecordedCloud&& cloud) {
        out.clouds.push_back(std::move(cloud));
        return Status::Ok();
      },
      &out.report);
  return out;
}

Rosbag2Options PointsOptions(const std::string& bag) {
  Rosbag2Options o;
  o.bag = bag;
  o.points_topic = test::kPointsTopic;
  o.sensor_id = "lidar";
  return o;
}

class Rosbag2Bags : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    events_ = new std::vector<test::BagEvent>(test::SceneEvents());
    sqlite_dir_ = new std::string(TempDir("sqlite"));
    test::WriteSqliteBag(*sqlite_dir_, *events_);
    mcap_dir_ = new std::string(TempDir("mcap"));
    chunks_ = new std::vector<test::McapWriter::RecordStart>;
    mcap_ = new std::string(test::SceneMcap(*events_, chunks_, chunk_records_));
    WriteBytes(*mcap_dir_ + "/scene.mcap", *mcap_);
  }
  static void TearDownTestSuite() {
    for (const std::string& dir : TempDirs()) fs::remove_all(dir);
  }
  static std::string McapPath() { return *mcap_dir_ + "/scene.mcap"; }

  static inline std::vector<test::BagEvent>* events_ = nullptr;
  static inline std::string *sqlite_dir_ = nullptr, *mcap_dir_ = nullptr, *mcap_ = nullptr;
  static inline std::vector<test::McapWriter::RecordStart>* chunks_ = nullptr;
  static inline std::size_t chunk_records_[3] = {};
};

Eigen::Isometry3d IsometryOf(const fusion::v1::RecordedPose& p) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = Eigen::Quaterniond(p.qw(), p.qx(), p.qy(), p.qz()).toRotationMatrix();
  T.translation() = Eigen::Vector3d(p.tx(), p.ty(), p.tz());
  return T;
}

void ExpectPose(const Eigen::Isometry3d& expected, const fusion::v1::RecordedPose& got,
                const std::string& what) {
  const Eigen::Isometry3d T = IsometryOf(got);
  EXPECT_LT((T.translation() - expected.translation()).norm(), 1e-6) << what;
  EXPECT_LT((T.linear() - expected.linear()).norm(), 1e-6) << what;
}

void ExpectLidarClouds(const std::vector<RecordedCloud>& clouds) {
  ASSERT_EQ(clouds.size(), test::kCloudTimes.size());
  for (std::size_t k = 0; k < clouds.size(); ++k) {
    const RecordedCloud& c = clouds[k];
    const double t = test::kCloudTimes[k];
    const std::string what = "cloud " + std::to_string(k);
    EXPECT_EQ(c.sensor_id(), "lidar");
    EXPECT_EQ(c.sequence_number(), k + 1);
    EXPECT_EQ(c.stamp().sec(), test::StampAt(t).sec) << what;
    EXPECT_EQ(c.stamp().nanosec(), test::StampAt(t).nanosec) << what;
    EXPECT_EQ(c.receive_time_unix_ns(), test::LogTimeNs(t + 0.02)) << what;
    // Between two tf samples 0.1 s apart: the interpolated pose is the trajectory's own.
    ExpectPose(test::T_map_odom() * test::T_odom_base(t) * test::T_base_lidar(), c.t_world_sensor(),
               what);
    ASSERT_EQ(c.width(), 8u);
    ASSERT_EQ(c.height(), 6u);
    ASSERT_EQ(c.xyz_f32le().size(), 8u * 6 * 12);
    for (int j = 0; j < 6; ++j) {
      for (int i = 0; i < 8; ++i) {
        float p[3];
        std::memcpy(p, c.xyz_f32le().data() + 12 * (j * 8 + i), 12);
        const Eigen::Vector3f e = test::BoardPoint(i, j);
        for (int a = 0; a < 3; ++a) {
          if (std::isnan(e[a])) {
            EXPECT_TRUE(std::isnan(p[a])) << what << " point " << i << "," << j;
          } else {
            EXPECT_EQ(p[a], e[a]) << what << " point " << i << "," << j;
          }
        }
      }
    }
  }
}

TEST_F(Rosbag2Bags, SqliteBagDirectory) {
  const Imported r = Import(PointsOptions(*sqlite_dir_));
  ASSERT_TRUE(r.status.ok()) << r.status.message();
  ExpectLidarClouds(r.clouds);
  // The cloud after the last tf is skipped and counted.
  EXPECT_EQ(r.report.cloud_messages, test::kCloudTimes.size() + 1);
  EXPECT_EQ(r.report.skipped.at("extrapolation"), 1u);
  EXPECT_EQ(r.report.messages, events_->size());
  EXPECT_EQ(r.report.transforms, 33u);
}

TEST_F(Rosbag2Bags, McapFileAndDirectoryGiveTheSameClouds) {
  const Imported sqlite = Import(PointsOptions(*sqlite_dir_ + "/scene.db3"));
  const Imported mcap = Import(PointsOptions(McapPath()));
  ASSERT_TRUE(mcap.status.ok()) << mcap.status.message();
  ASSERT_EQ(chunks_->size(), 3u);
  ExpectLidarClouds(mcap.clouds);
  ASSERT_EQ(sqlite.clouds.size(), mcap.clouds.size());
  for (std::size_t k = 0; k < mcap.clouds.size(); ++k) {
    RecordedCloud a = sqlite.clouds[k], b = mcap.clouds[k];
    a.clear_origin();
    b.clear_origin();
    EXPECT_EQ(a.SerializeAsString(), b.SerializeAsString()) << "cloud " << k;
  }
  test::WriteRosbag2Metadata(*mcap_dir_, "mcap", {"scene.mcap"});
  const Imported directory = Import(PointsOptions(*mcap_dir_));
  ASSERT_TRUE(directory.status.ok()) << directory.status.message();
  EXPECT_EQ(directory.clouds.size(), mcap.clouds.size());
  fs::remove(*mcap_dir_ + "/metadata.yaml");
}

TEST_F(Rosbag2Bags, DepthImagesWithCameraInfoAndStride) {
  for (const std::string& bag : {*sqlite_dir_, McapPath()}) {
    Rosbag2Options o;
    o.bag = bag;
    o.depth_topic = test::kDepthTopic;
    o.camera_info_topic = test::kInfoTopic;
    o.stride = 2;
    const Imported r = Import(o);
    ASSERT_TRUE(r.status.ok()) << bag << ": " << r.status.message();
    ASSERT_EQ(r.clouds.size(), test::kDepthTimes.size()) << bag;
    for (std::size_t k = 0; k < r.clouds.size(); ++k) {
      const RecordedCloud& c = r.clouds[k];
      const double t = test::kDepthTimes[k];
      ExpectPose(test::T_map_odom() * test::T_odom_base(t) * test::T_base_camera(),
                 c.t_world_sensor(), bag);
      ASSERT_EQ(c.width(), 4u);
      ASSERT_EQ(c.height(), 3u);
      for (std::uint32_t row = 0; row < 3; ++row) {
        for (std::uint32_t col = 0; col < 4; ++col) {
          float p[3];
          std::memcpy(p, c.xyz_f32le().data() + 12 * (row * 4 + col), 12);
          const double u = 2.0 * col, v = 2.0 * row;
          if (col == 0 && row == 0) {
            EXPECT_TRUE(std::isnan(p[2]));
            continue;
          }
          EXPECT_FLOAT_EQ(p[2], 2.0f);
          EXPECT_FLOAT_EQ(p[0], static_cast<float>((u - test::kCx) * 2.0 / test::kFx));
          EXPECT_FLOAT_EQ(p[1], static_cast<float>((v - test::kCy) * 2.0 / test::kFy));
        }
      }
    }
  }
}

TEST_F(Rosbag2Bags, MissingTopicListsTheBagsTopics) {
  Rosbag2Options o = PointsOptions(*sqlite_dir_);
  o.points_topic = "/points";
  const Imported r = Import(o);
  EXPECT_FALSE(r.status.ok());
  EXPECT_THAT(r.status.message(), HasSubstr("topic /points is not in"));
  EXPECT_THAT(r.status.message(),
              HasSubstr("/lidar/points (sensor_msgs/msg/PointCloud2, 7 messages)"));
  EXPECT_THAT(r.status.message(), HasSubstr("/tf (tf2_msgs/msg/TFMessage, 30 messages)"));
  o.points_topic = "/tf";
  EXPECT_THAT(Import(o).status.message(),
              HasSubstr("topic /tf is tf2_msgs/msg/TFMessage, not sensor_msgs/msg/PointCloud2"));
  o.points_topic = test::kPointsTopic;
  o.tf_topic = test::kDepthTopic;
  EXPECT_THAT(Import(o).status.message(),
              HasSubstr("topic /camera/depth/image_raw is sensor_msgs/msg/Image, not "
                        "tf2_msgs/msg/TFMessage"));
  o = PointsOptions(McapPath());
  o.map_frame = "world";  // no such frame: every cloud skipped, which is an error
  const Imported none = Import(o);
  EXPECT_THAT(none.status.message(), HasSubstr("none of the 7 clouds on /lidar/points"));
  EXPECT_THAT(none.status.message(), HasSubstr("no_transform"));
  EXPECT_TRUE(none.clouds.empty());
}

TEST_F(Rosbag2Bags, UnknownStorageAndCompressedBags) {
  const std::string dir = TempDir("unknown");
  WriteBytes(dir + "/junk.db3", "this is not a bag at all");
  EXPECT_THAT(Import(PointsOptions(dir + "/junk.db3")).status.message(),
              HasSubstr("unknown storage: neither sqlite3 nor MCAP"));
  test::WriteRosbag2Metadata(dir, "rosbag_v1", {"junk.db3"});
  EXPECT_THAT(Import(PointsOptions(dir)).status.message(),
              HasSubstr("unknown storage 'rosbag_v1'"));
  test::WriteRosbag2Metadata(dir, "sqlite3", {"junk.db3.zstd"}, "zstd");
  EXPECT_THAT(Import(PointsOptions(dir)).status.message(),
              HasSubstr("compression_format zstd is not supported"));
  EXPECT_THAT(Import(PointsOptions(dir + "/nothing")).status.message(), HasSubstr("no such bag"));
}

// The clouds of a broken import are the first of the full import's.
void ExpectPrefix(const std::vector<RecordedCloud>& part, const std::string& what) {
  ASSERT_LE(part.size(), test::kCloudTimes.size()) << what;
  for (std::size_t k = 0; k < part.size(); ++k) {
    EXPECT_EQ(part[k].stamp().nanosec(), test::StampAt(test::kCloudTimes[k]).nanosec) << what;
  }
}

TEST_F(Rosbag2Bags, McapCutInTheSecondChunkKeepsTheFirstChunksClouds) {
  const test::McapWriter::RecordStart second = (*chunks_)[1];
  const std::string path = TempDir("cut") + "/cut.mcap";
  WriteBytes(path, mcap_->substr(0, second.offset + 100));
  const Imported r = Import(PointsOptions(path));
  EXPECT_FALSE(r.status.ok());
  EXPECT_THAT(r.status.message(), HasSubstr("record " + std::to_string(chunk_records_[1]) +
                                            " (Chunk) at byte " + std::to_string(second.offset)));
  EXPECT_THAT(r.status.message(), HasSubstr("truncated"));
  ASSERT_EQ(r.clouds.size(), 2u);  // 0.15 s and 0.55 s
  ExpectPrefix(r.clouds, "cut");
}

TEST_F(Rosbag2Bags, McapFlippedBytesAreCaughtAtTheirChunk) {
  const std::string path = TempDir("flip") + "/flip.mcap";
  for (int chunk = 0; chunk < 3; ++chunk) {
    std::string bytes = *mcap_;
    bytes[(*chunks_)[chunk].offset + 200] ^= 0x5A;  // inside the records (compressed or not)
    WriteBytes(path, bytes);
    const Imported r = Import(PointsOptions(path));
    EXPECT_FALSE(r.status.ok()) << "chunk " << chunk;
    EXPECT_THAT(r.status.message(),
                HasSubstr("record " + std::to_string(chunk_records_[chunk]) + " (Chunk) at byte " +
                          std::to_string((*chunks_)[chunk].offset)))
        << "chunk " << chunk;
    EXPECT_EQ(r.clouds.size(), 2u * chunk) << r.status.message();
    ExpectPrefix(r.clouds, "flip in chunk " + std::to_string(chunk));
  }
}

// A chunk whose uncompressed size was damaged is refused before that size is allocated.
TEST_F(Rosbag2Bags, McapChunkSizeClaimsAreCheckedAgainstTheFrames) {
  const std::string path = TempDir("sizes") + "/sizes.mcap";
  const char* const kExpected[3] = {"uncompressed records of", "zstd frame holds", "cannot hold"};
  for (int chunk = 0; chunk < 3; ++chunk) {
    std::string bytes = *mcap_;
    const std::uint64_t claim = (std::uint64_t{1} << 30) - 1;  // just under the 1 GiB limit
    std::memcpy(&bytes[(*chunks_)[chunk].offset + 9 + 16], &claim, 8);  // uncompressed_size
    WriteBytes(path, bytes);
    const Imported r = Import(PointsOptions(path));
    EXPECT_THAT(r.status.message(), HasSubstr(kExpected[chunk])) << "chunk " << chunk;
    EXPECT_EQ(r.clouds.size(), 2u * chunk);
  }
}

TEST_F(Rosbag2Bags, McapCutAnywhereIsAnErrorNeverACrash) {
  const std::string path = TempDir("cuts") + "/cut.mcap";
  for (std::size_t n = 0; n < mcap_->size(); n += 61) {
    WriteBytes(path, mcap_->substr(0, n));
    const Imported r = Import(PointsOptions(path));
    EXPECT_FALSE(r.status.ok()) << "cut at " << n;
    ExpectPrefix(r.clouds, "cut at " + std::to_string(n));
  }
  // At a record boundary after all chunks: every cloud, and the missing footer reported.
  const std::string whole = *mcap_;
  WriteBytes(path, whole.substr(0, whole.size() - 8));  // no closing magic
  const Imported r = Import(PointsOptions(path));
  EXPECT_THAT(r.status.message(), HasSubstr("no MCAP magic after the Footer"));
  EXPECT_EQ(r.clouds.size(), test::kCloudTimes.size());
}

TEST_F(Rosbag2Bags, SqliteCorruptMessageIsSkippedAndReported) {
  std::vector<test::BagEvent> events = *events_;
  int clouds = 0;
  std::size_t broken = 0;
  for (std::size_t i = 0; i < events.size(); ++i) {
    if (events[i].topic == test::kPointsTopic && ++clouds == 3) {
      events[i].data.resize(events[i].data.size() / 2);  // 3rd cloud cut in half
      broken = i + 1;
    }
  }
  const std::string dir = TempDir("sqlite_corrupt");
  test::WriteSqliteBag(dir, events);
  const Imported r = Import(PointsOptions(dir));
  EXPECT_FALSE(r.status.ok());
  EXPECT_THAT(r.status.message(), HasSubstr("1 messages do not decode"));
  EXPECT_THAT(r.status.message(), HasSubstr("message " + std::to_string(broken) +
                                            " on /lidar/points: PointCloud2.data"));
  EXPECT_EQ(r.clouds.size(), test::kCloudTimes.size() - 1);
  EXPECT_EQ(r.report.skipped.at("cdr"), 1u);
}

TEST_F(Rosbag2Bags, SqliteTruncatedFileIsAnError) {
  const std::string dir = TempDir("sqlite_cut");
  std::ifstream in(*sqlite_dir_ + "/scene.db3", std::ios::binary);
  const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  for (const std::size_t n :
       {bytes.size() / 2, bytes.size() - 100, std::size_t{4096}, std::size_t{50}}) {
    WriteBytes(dir + "/scene.db3", bytes.substr(0, n));
    const Imported r = Import(PointsOptions(dir + "/scene.db3"));
    EXPECT_FALSE(r.status.ok()) << n << " of " << bytes.size() << ": " << r.clouds.size();
    ExpectPrefix(r.clouds, "sqlite cut at " + std::to_string(n));
  }
}

TEST(Rosbag2OptionsTest, TopicsAreCheckedTogether) {
  Rosbag2Options o;
  o.bag = "x";
  EXPECT_THAT(CheckRosbag2Options(o).message(), HasSubstr("needs --points-topic or --depth-topic"));
  o.depth_topic = "/d";
  EXPECT_THAT(CheckRosbag2Options(o).message(), HasSubstr("needs --camera-info-topic"));
  o.camera_info_topic = "/i";
  EXPECT_TRUE(CheckRosbag2Options(o).ok());
  o.points_topic = "/p";
  EXPECT_THAT(CheckRosbag2Options(o).message(), HasSubstr("not both"));
  Status s;
  EXPECT_TRUE(ApplyRosbag2Option("--stride", "0", &o, &s));
  EXPECT_FALSE(s.ok());
  s = Status::Ok();
  EXPECT_TRUE(ApplyRosbag2Option("--map-frame", "world", &o, &s));
  EXPECT_TRUE(s.ok());
  EXPECT_EQ(o.map_frame, "world");
  EXPECT_FALSE(ApplyRosbag2Option("--start-time", "1", &o, &s));
}

}  // namespace
}  // namespace fusion::clients
