// Importers on the real samples in ../shared/data (skipped when absent) and on small files
// written here.
#include "fusion/clients/importers.h"

#include <gtest/gtest.h>
#include <octomap/ScanGraph.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "fusion/clients/lzf.h"

namespace fusion::clients {
namespace {

const std::string kData = FUSION_SHARED_DATA_DIR;

bool Exists(const std::string& path) { return access(path.c_str(), R_OK) == 0; }

std::string TempPath(const std::string& name) {
  return ::testing::TempDir() + "/" + std::to_string(getpid()) + "_" + name;
}

void WriteFile(const std::string& path, const std::string& bytes) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
}

// World point of a sensor-frame point: R(q) p + t.
void ToWorld(const fusion::v1::RecordedPose& T, const float p[3], double out[3]) {
  const double x = T.qx(), y = T.qy(), z = T.qz(), w = T.qw();
  const double R[3][3] = {{1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)},
                          {2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)},
                          {2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)}};
  const double t[3] = {T.tx(), T.ty(), T.tz()};
  for (int r = 0; r < 3; ++r) out[r] = R[r][0] * p[0] + R[r][1] * p[1] + R[r][2] * p[2] + t[r];
}

// ---------------------------------------------------------------------------------------------
// TUM RGB-D

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

// ---------------------------------------------------------------------------------------------
// LZF and PCD

TEST(LzfTest, LiteralsAndOverlappingBackReference) {
  // "abc" literal, then a match of length 6 at distance 3: "abcabcabc".
  const unsigned char in[] = {2, 'a', 'b', 'c', (6 - 2) << 5, 3 - 1};
  char out[16] = {};
  ASSERT_EQ(LzfDecompress(in, sizeof in, out, sizeof out), 9u);
  EXPECT_EQ(std::string(out, 9), "abcabcabc");
  // Too small an output buffer, a reference before the start, a truncated literal: 0.
  EXPECT_EQ(LzfDecompress(in, sizeof in, out, 8), 0u);
  const unsigned char bad_ref[] = {0, 'a', (3 - 2) << 5, 5};
  EXPECT_EQ(LzfDecompress(bad_ref, sizeof bad_ref, out, sizeof out), 0u);
  const unsigned char short_literal[] = {5, 'a'};
  EXPECT_EQ(LzfDecompress(short_literal, sizeof short_literal, out, sizeof out), 0u);
}

// LZF "compression" with literal runs only: valid input for any decompressor.
std::string LzfLiterals(const std::string& raw) {
  std::string out;
  for (std::size_t i = 0; i < raw.size(); i += 32) {
    const std::size_t n = std::min<std::size_t>(32, raw.size() - i);
    out.push_back(static_cast<char>(n - 1));
    out.append(raw, i, n);
  }
  return out;
}

std::string PcdHeader(std::uint32_t width, std::uint32_t height, const std::string& data,
                      const std::string& viewpoint = "0 0 0 1 0 0 0") {
  std::ostringstream h;
  h << "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS x y z rgb\n"
    << "SIZE 4 4 4 4\nTYPE F F F F\nCOUNT 1 1 1 1\nWIDTH " << width << "\nHEIGHT " << height
    << "\nVIEWPOINT " << viewpoint << "\nPOINTS " << width * height << "\nDATA " << data << "\n";
  return h.str();
}

// The same points written in all three encodings decode identically.
void CheckEncodingsAgree(const std::vector<float>& xyz, std::uint32_t width, std::uint32_t height) {
  const std::size_t n = static_cast<std::size_t>(width) * height;
  std::ostringstream ascii;
  std::string binary, columns[4];
  for (std::size_t i = 0; i < n; ++i) {
    const float rgb = 4.2e-39f;
    const float point[4] = {xyz[3 * i], xyz[3 * i + 1], xyz[3 * i + 2], rgb};
    binary.append(reinterpret_cast<const char*>(point), 16);
    for (int f = 0; f < 4; ++f) columns[f].append(reinterpret_cast<const char*>(&point[f]), 4);
  }
  // Full precision, NaN spelled "nan".
  for (std::size_t i = 0; i < n; ++i) {
    for (int a = 0; a < 3; ++a) {
      const float v = xyz[3 * i + a];
      if (std::isnan(v)) {
        ascii << "nan ";
      } else {
        char text[32];
        std::snprintf(text, sizeof text, "%.9g ", v);
        ascii << text;
      }
    }
    ascii << "7\n";
  }
  const std::string raw = columns[0] + columns[1] + columns[2] + columns[3];
  const std::string compressed = LzfLiterals(raw);
  std::uint32_t sizes[2] = {static_cast<std::uint32_t>(compressed.size()),
                            static_cast<std::uint32_t>(raw.size())};

  const std::string paths[3] = {TempPath("a.pcd"), TempPath("b.pcd"), TempPath("c.pcd")};
  WriteFile(paths[0], PcdHeader(width, height, "ascii") + ascii.str());
  WriteFile(paths[1], PcdHeader(width, height, "binary") + binary);
  WriteFile(paths[2], PcdHeader(width, height, "binary_compressed") +
                          std::string(reinterpret_cast<const char*>(sizes), 8) + compressed);
  for (const std::string& path : paths) {
    fusion::v1::RecordedCloud cloud;
    const Status s = ReadPcd(path, &cloud);
    ASSERT_TRUE(s.ok()) << path << ": " << s.message();
    EXPECT_EQ(cloud.width(), width);
    EXPECT_EQ(cloud.height(), height);
    ASSERT_EQ(cloud.xyz_f32le().size(), xyz.size() * 4);
    for (std::size_t i = 0; i < n; ++i) {
      float p[3];
      GetPoint(cloud, i, p);
      for (int a = 0; a < 3; ++a) {
        const float want = xyz[3 * i + a];
        if (std::isnan(want)) {
          ASSERT_TRUE(std::isnan(p[a])) << path << " point " << i;
        } else {
          ASSERT_EQ(p[a], want) << path << " point " << i;
        }
      }
    }
    std::remove(path.c_str());
  }
}

TEST(PcdTest, SmallCloudInAllEncodings) {
  std::vector<float> xyz;
  for (int i = 0; i < 12; ++i) {
    if (i == 5) {
      xyz.insert(xyz.end(), {NAN, NAN, NAN});
    } else {
      xyz.insert(xyz.end(),
                 {0.1f * static_cast<float>(i), -0.25f, 1.0f + 0.3f * static_cast<float>(i)});
    }
  }
  CheckEncodingsAgree(xyz, 4, 3);
}

TEST(PcdTest, ViewpointBecomesThePoseAndPointsMoveIntoTheSensorFrame) {
  const std::string path = TempPath("viewpoint.pcd");
  // Sensor at (1, 0, 0) rotated 90 degrees about z; a point 2 m along world +y from it is
  // 2 m along the sensor's +x.
  const double h = std::sqrt(0.5);
  WriteFile(path,
            PcdHeader(1, 1, "ascii", "1 0 0 " + std::to_string(h) + " 0 0 " + std::to_string(h)) +
                "1 2 0 0\n");
  fusion::v1::RecordedCloud cloud;
  const Status s = ReadPcd(path, &cloud);
  ASSERT_TRUE(s.ok()) << s.message();
  EXPECT_NEAR(cloud.t_world_sensor().tx(), 1.0, 1e-9);
  EXPECT_NEAR(cloud.t_world_sensor().qz(), h, 1e-6);
  float p[3];
  GetPoint(cloud, 0, p);
  EXPECT_NEAR(p[0], 2.0, 1e-5);
  EXPECT_NEAR(p[1], 0.0, 1e-5);
  EXPECT_NEAR(p[2], 0.0, 1e-5);
  std::remove(path.c_str());
}

TEST(PcdTest, BrokenFilesAreClearErrors) {
  const std::string path = TempPath("broken.pcd");
  fusion::v1::RecordedCloud cloud;
  WriteFile(path, PcdHeader(4, 1, "binary") + std::string(20, '\0'));
  Status s = ReadPcd(path, &cloud);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("needs 64"), std::string::npos) << s.message();

  WriteFile(path, PcdHeader(2, 1, "ascii") + "1 2 3 4\n1 2\n");
  s = ReadPcd(path, &cloud);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("expected 4 values, got 2"), std::string::npos) << s.message();

  WriteFile(path,
            "VERSION 0.7\nFIELDS x y\nSIZE 4 4\nTYPE F F\nWIDTH 1\nHEIGHT 1\nDATA ascii\n1 2\n");
  s = ReadPcd(path, &cloud);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("no field 'z'"), std::string::npos) << s.message();

  std::uint32_t sizes[2] = {10, 64};
  WriteFile(path, PcdHeader(4, 1, "binary_compressed") +
                      std::string(reinterpret_cast<const char*>(sizes), 8) +
                      std::string(10, '\x60'));
  s = ReadPcd(path, &cloud);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("corrupt LZF"), std::string::npos) << s.message();
  std::remove(path.c_str());
}

// Inputs that crashed the importer once (hostile testing): a header whose DATA line ends the
// file (heap-buffer-overflow in binary, std::out_of_range in ascii), and a point size that
// overflowed the size computation (SIGSEGV, binary and compressed).
TEST(PcdTest, CrashInputsAreCleanErrors) {
  const std::string path = TempPath("crash.pcd");
  const std::string header =
      "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 4\nHEIGHT 1\n"
      "POINTS 4\n";
  std::string many_fields = "VERSION 0.7\nFIELDS x y z";
  std::string sizes = "\nSIZE 4 4 4", types = "\nTYPE F F F", counts = "\nCOUNT 1 1 1";
  for (int i = 0; i < 40; ++i) {
    many_fields += " f" + std::to_string(i);
    sizes += " 1048576";
    types += " U";
    counts += " 1048576";
  }
  many_fields += sizes + types + counts + "\nWIDTH 16\nHEIGHT 1\nPOINTS 16\n";
  const std::pair<std::string, std::string> cases[] = {
      {header + "DATA binary", "needs 48"},
      {header + "DATA ascii", "ascii data ends after 0 of 4"},
      {header + "DATA binary_compressed", "lacks its size header"},
      {many_fields + "DATA binary\n" + std::string(64, '\0'), "more than 1 MiB"},
      {many_fields + "DATA binary_compressed\n" + std::string(64, '\0'), "more than 1 MiB"},
  };
  for (const auto& [bytes, why] : cases) {
    WriteFile(path, bytes);
    fusion::v1::RecordedCloud cloud;
    const Status s = ReadPcd(path, &cloud);
    ASSERT_FALSE(s.ok()) << why;
    EXPECT_NE(s.message().find(why), std::string::npos) << s.message();
  }
  std::remove(path.c_str());
}

TEST(PcdTest, RealStereoFrame) {
  const std::string path = kData + "/pcl_stereo/table_scene_mug_stereo_textured.pcd";
  if (!Exists(path)) GTEST_SKIP() << "PCL sample not found at " << path;
  // Its VIEWPOINT "0 0 0 0 1 0 0" (qw qx qy qz) is a half turn about x: applied, every point
  // would lie behind the camera, which the importer can tell.
  fusion::v1::RecordedCloud as_stored;
  ASSERT_TRUE(ReadPcd(path, &as_stored, /*apply_viewpoint=*/true).ok());
  EXPECT_NEAR(as_stored.t_world_sensor().qx(), 1.0, 1e-12);
  EXPECT_GT(FractionBehindSensor(as_stored), 0.99);

  fusion::v1::RecordedCloud cloud;
  const Status s = ReadPcd(path, &cloud, /*apply_viewpoint=*/false);
  ASSERT_TRUE(s.ok()) << s.message();
  ASSERT_EQ(cloud.width(), 640u);
  ASSERT_EQ(cloud.height(), 480u);
  ASSERT_EQ(cloud.xyz_f32le().size(), 640u * 480u * 12u);
  EXPECT_EQ(cloud.t_world_sensor().qw(), 1.0);
  EXPECT_EQ(FractionBehindSensor(cloud), 0.0);
  std::size_t nan = 0, valid = 0;
  for (std::size_t i = 0; i < 640u * 480u; ++i) {
    float p[3];
    GetPoint(cloud, i, p);
    if (std::isnan(p[0]) || std::isnan(p[1]) || std::isnan(p[2])) {
      ++nan;
      continue;
    }
    ++valid;
    ASSERT_GT(p[2], 0.2f) << "point " << i;  // in front of the camera
    ASSERT_LT(p[2], 5.0f) << "point " << i;  // a table scene, not a hall
    ASSERT_LT(std::abs(p[0]), 3.0f);
    ASSERT_LT(std::abs(p[1]), 3.0f);
  }
  EXPECT_GT(nan, 1000u);
  EXPECT_GT(valid, 100000u);

  // A 16 x 12 sub-grid re-encoded as ascii, binary and binary_compressed decodes the same.
  std::vector<float> sub;
  for (std::uint32_t v = 0; v < 480; v += 40) {
    for (std::uint32_t u = 0; u < 640; u += 40) {
      float p[3];
      GetPoint(cloud, static_cast<std::size_t>(v) * 640 + u, p);
      sub.insert(sub.end(), p, p + 3);
    }
  }
  CheckEncodingsAgree(sub, 16, 12);
}

// ---------------------------------------------------------------------------------------------
// Scans and scan graphs

TEST(ScanTest, RealLaserScanHas88206Points) {
  const std::string path = kData + "/octomap_laser_scan/scan.dat.bz2";
  if (!Exists(path)) GTEST_SKIP() << "OctoMap scan not found at " << path;
  fusion::v1::RecordedPose pose;
  pose.set_tz(0.5);
  pose.set_qw(1.0);
  std::vector<fusion::v1::RecordedCloud> clouds;
  const Status s = ReadXyzScan(path, pose, &clouds);
  ASSERT_TRUE(s.ok()) << s.message();
  ASSERT_EQ(clouds.size(), 1u);
  EXPECT_EQ(clouds[0].width(), 88206u);
  EXPECT_EQ(clouds[0].height(), 1u);
  EXPECT_EQ(clouds[0].t_world_sensor().tz(), 0.5);
  double max_range = 0, min_range = 1e9;
  for (std::size_t i = 0; i < 88206; ++i) {
    float p[3];
    GetPoint(clouds[0], i, p);
    const double r = std::sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2]);
    max_range = std::max(max_range, r);
    min_range = std::min(min_range, r);
  }
  EXPECT_GT(min_range, 0.4);  // README: ranges 0.47-29 m
  EXPECT_LT(max_range, 30.0);
}

TEST(ScanTest, NodeLinesSplitCloudsAndBadLinesAreNamed) {
  const std::string path = TempPath("scan.txt");
  WriteFile(path, "# comment\nNODE 1 2 3 0 0 0\n0 0 1\n0 1 1\nNODE 0 0 0 0 0 1.5707963\n5 5 5\n");
  fusion::v1::RecordedPose pose;
  pose.set_qw(1.0);
  std::vector<fusion::v1::RecordedCloud> clouds;
  Status s = ReadXyzScan(path, pose, &clouds);
  ASSERT_TRUE(s.ok()) << s.message();
  ASSERT_EQ(clouds.size(), 2u);
  EXPECT_EQ(clouds[0].width(), 2u);
  EXPECT_EQ(clouds[0].t_world_sensor().ty(), 2.0);
  EXPECT_EQ(clouds[1].width(), 1u);
  EXPECT_NEAR(clouds[1].t_world_sensor().qz(), std::sqrt(0.5), 1e-6);

  WriteFile(path, "0 0 1\n0 x 1\n");
  s = ReadXyzScan(path, pose, &clouds);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find(":2:"), std::string::npos) << s.message();
  std::remove(path.c_str());
}

TEST(ScanGraphTest, GraphWrittenByOctoMapImports) {
  octomap::ScanGraph graph;
  for (int n = 0; n < 3; ++n) {
    auto* scan = new octomap::Pointcloud();  // the graph owns it
    for (int i = 0; i <= n; ++i)
      scan->push_back(1.0f + static_cast<float>(i), 0.0f, 0.5f * static_cast<float>(n));
    graph.addNode(scan, octomap::pose6d(static_cast<double>(n), 0, 0.25, 0, 0, 0.3 * n));
  }
  graph.connectPrevious();
  const std::string path = TempPath("three.graph");
  ASSERT_TRUE(graph.writeBinary(path));

  std::vector<fusion::v1::RecordedCloud> clouds;
  const Status s = ReadScanGraph(path, &clouds);
  ASSERT_TRUE(s.ok()) << s.message();
  ASSERT_EQ(clouds.size(), 3u);
  for (int n = 0; n < 3; ++n) {
    const auto& cloud = clouds[static_cast<std::size_t>(n)];
    EXPECT_EQ(cloud.width(), static_cast<std::uint32_t>(n + 1));
    EXPECT_NEAR(cloud.t_world_sensor().tx(), n, 1e-6);
    EXPECT_NEAR(cloud.t_world_sensor().tz(), 0.25, 1e-6);
    EXPECT_NEAR(cloud.t_world_sensor().qz(), std::sin(0.15 * n), 1e-6);
    EXPECT_NEAR(cloud.t_world_sensor().qw(), std::cos(0.15 * n), 1e-6);
    float p[3];
    GetPoint(cloud, static_cast<std::size_t>(n), p);
    EXPECT_FLOAT_EQ(p[0], 1.0f + static_cast<float>(n));
    EXPECT_FLOAT_EQ(p[2], 0.5f * static_cast<float>(n));
  }
  WriteFile(path, "garbage");
  EXPECT_FALSE(ReadScanGraph(path, &clouds).ok());
  EXPECT_FALSE(ReadScanGraph(TempPath("missing.graph"), &clouds).ok());
  std::remove(path.c_str());
}

}  // namespace
}  // namespace fusion::clients
