// TUM RGB-D importer on the real sample in ../shared/data (skipped when absent) and on broken
// files written here.
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "fusion/clients/importers.h"
#include "import_test_util.h"

namespace fusion::clients::import_test {
namespace {

class TumTest : public ::testing::Test {
 protected:
  void SetUp() override {
    directory_ = kData + "/tum_fr2_pioneer_slam2";
    if (!Exists(directory_ + "/groundtruth.txt")) {
      GTEST_SKIP() << "TUM sample not found at " << directory_ << " (see ../shared/data/README.md)";
    }
  }
  std::string directory_;
};

TEST_F(TumTest, TenFramesWithGroundTruthPosesAndDepth) {
  TumOptions options;
  options.directory = directory_;
  std::vector<fusion::v1::RecordedCloud> clouds;
  const Status s = ImportTum(options, [&](fusion::v1::RecordedCloud&& c) {
    clouds.push_back(std::move(c));
    return Status::Ok();
  });
  ASSERT_TRUE(s.ok()) << s.message();
  ASSERT_EQ(clouds.size(), 10u);

  std::ifstream list(directory_ + "/groundtruth.txt");
  std::string line;
  std::size_t k = 0;
  while (std::getline(list, line)) {
    if (line.empty() || line[0] == '#') continue;
    std::istringstream fields(line);
    std::string file;
    double p[7];
    fields >> file >> p[0] >> p[1] >> p[2] >> p[3] >> p[4] >> p[5] >> p[6];
    ASSERT_LT(k, clouds.size());
    const fusion::v1::RecordedCloud& cloud = clouds[k];
    const auto& T = cloud.t_world_sensor();
    EXPECT_NEAR(T.tx(), p[0], 1e-9);
    EXPECT_NEAR(T.ty(), p[1], 1e-9);
    EXPECT_NEAR(T.tz(), p[2], 1e-9);
    EXPECT_NEAR(T.qx(), p[3], 1e-3);
    EXPECT_NEAR(T.qw(), p[6], 1e-3);
    EXPECT_EQ(cloud.width(), 640u);
    EXPECT_EQ(cloud.height(), 480u);
    ASSERT_EQ(cloud.xyz_f32le().size(), 640u * 480u * 12u);
    EXPECT_EQ(cloud.sequence_number(), k + 1);
    EXPECT_EQ(cloud.sensor_id(), "tum");
    // Stamp from the file name, e.g. depth/1311877813.991479.png.
    const double stamp = cloud.stamp().sec() + 1e-9 * cloud.stamp().nanosec();
    EXPECT_NEAR(stamp, std::stod(file.substr(6, file.size() - 10)), 1e-6);

    // Every pixel's depth equals png / 5000, with x, y from the pinhole model.
    std::uint32_t w = 0, h = 0;
    std::vector<std::uint16_t> png;
    ASSERT_TRUE(ReadPng16(directory_ + "/" + file, &w, &h, &png).ok());
    const std::size_t centre = 240 * 640 + 320;
    float c[3];
    GetPoint(cloud, centre, c);
    if (png[centre] == 0) {
      EXPECT_TRUE(std::isnan(c[2]));
    } else {
      EXPECT_FLOAT_EQ(c[2], static_cast<float>(png[centre] / 5000.0));
      EXPECT_NEAR(c[0], (320 - 325.1) * c[2] / 520.9, 1e-5);
      EXPECT_NEAR(c[1], (240 - 249.7) * c[2] / 521.0, 1e-5);
    }
    std::size_t missing = 0, valid = 0, floor = 0;
    std::vector<double> world_z;
    for (std::size_t i = 0; i < png.size(); ++i) {
      float q[3];
      GetPoint(cloud, i, q);
      if (png[i] == 0) {
        ++missing;
        ASSERT_TRUE(std::isnan(q[0]) && std::isnan(q[1]) && std::isnan(q[2]));
        continue;
      }
      ASSERT_FLOAT_EQ(q[2], static_cast<float>(png[i] / 5000.0)) << "pixel " << i;
      ++valid;
      double wp[3];
      ToWorld(T, q, wp);
      world_z.push_back(wp[2]);
      if (std::abs(wp[2]) < 0.1) ++floor;
    }
    EXPECT_GT(missing, 0u);
    ASSERT_GT(valid, 100000u);
    // The floor is the lowest surface: z ~ 0 (+-0.1 m) in the world frame, and visible.
    std::sort(world_z.begin(), world_z.end());
    EXPECT_NEAR(world_z[world_z.size() / 200], 0.0, 0.1) << file;  // 0.5th percentile
    EXPECT_GT(floor, valid / 20) << file << ": too few floor points";
    ++k;
  }
  EXPECT_EQ(k, 10u);
}

TEST_F(TumTest, StrideDecimatesAndMaxFramesStops) {
  TumOptions options;
  options.directory = directory_;
  options.stride = 4;
  options.max_frames = 3;
  std::vector<fusion::v1::RecordedCloud> clouds;
  ASSERT_TRUE(ImportTum(options, [&](fusion::v1::RecordedCloud&& c) {
                clouds.push_back(std::move(c));
                return Status::Ok();
              }).ok());
  ASSERT_EQ(clouds.size(), 3u);
  EXPECT_EQ(clouds[0].width(), 160u);
  EXPECT_EQ(clouds[0].height(), 120u);
  EXPECT_EQ(clouds[0].xyz_f32le().size(), 160u * 120u * 12u);
}

TEST_F(TumTest, TruncatedPngIsAnErrorNotACrash) {
  std::ifstream list(directory_ + "/groundtruth.txt");
  std::string line, file;
  while (std::getline(list, line) && (line.empty() || line[0] == '#')) {
  }
  file = line.substr(0, line.find(' '));
  std::ifstream in(directory_ + "/" + file, std::ios::binary);
  const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const std::string path = TempPath("torn.png");
  WriteFile(path, bytes.substr(0, bytes.size() / 2));
  std::uint32_t w = 0, h = 0;
  std::vector<std::uint16_t> values;
  const Status s = ReadPng16(path, &w, &h, &values);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("corrupt PNG"), std::string::npos) << s.message();
  std::remove(path.c_str());
}

TEST(TumErrorTest, MissingDirectoryIsAClearError) {
  TumOptions options;
  options.directory = "/nonexistent/tum";
  const Status s = ImportTum(options, [](fusion::v1::RecordedCloud&&) { return Status::Ok(); });
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("/nonexistent/tum/groundtruth.txt"), std::string::npos) << s.message();
}

}  // namespace
}  // namespace fusion::clients::import_test
