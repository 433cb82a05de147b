// LZF and the PCD importer: small clouds written here in every encoding, broken and hostile
// files, and the real stereo frame in ../shared/data (skipped when absent).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <sstream>
#include <string>
#include <vector>

#include "fusion/clients/importers.h"
#include "fusion/clients/lzf.h"
#include "import_test_util.h"

namespace fusion::clients::import_test {
namespace {

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

}  // namespace
}  // namespace fusion::clients::import_test
