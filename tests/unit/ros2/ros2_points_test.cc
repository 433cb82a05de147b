// ROS 2 range messages to points (fusion/ros2/points.h): PointCloud2 with any layout and byte
// order, depth images 16UC1 / 32FC1 with a stride, and every rejection with its reason.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>

#include "fusion/ros2/points.h"

namespace fusion::ros2 {
namespace {

using ::testing::HasSubstr;
using Bytes = std::vector<std::uint8_t>;

void PutFloat(float v, bool big_endian, std::uint8_t* p) {
  std::memcpy(p, &v, 4);
  if (big_endian) std::swap(p[0], p[3]), std::swap(p[1], p[2]);
}

// A cloud of `points` (x y z) with fields z, pad, x, y at offsets 8, -, 0, 4 of a 20-byte
// point (+ an intensity field at 16), rows padded by 6 bytes: layout nothing assumes.
struct TestCloud {
  PointCloud2 msg;
  Bytes data;
};
TestCloud MakeCloud(const std::vector<std::array<float, 3>>& points, std::uint32_t width,
                    bool big_endian) {
  TestCloud c;
  c.msg.width = width;
  c.msg.height = static_cast<std::uint32_t>(points.size()) / width;
  c.msg.fields = {{"intensity", 16, PointField::FLOAT32, 1},
                  {"z", 12, PointField::FLOAT32, 1},
                  {"x", 0, PointField::FLOAT32, 1},
                  {"y", 4, PointField::FLOAT32, 1}};
  c.msg.point_step = 20;
  c.msg.row_step = 20 * width + 6;
  c.msg.is_bigendian = big_endian;
  c.data.assign(std::size_t{c.msg.row_step} * c.msg.height, 0xAB);
  for (std::size_t i = 0; i < points.size(); ++i) {
    std::uint8_t* p = c.data.data() + (i / width) * c.msg.row_step + (i % width) * 20;
    PutFloat(points[i][0], big_endian, p + 0);
    PutFloat(points[i][1], big_endian, p + 4);
    PutFloat(points[i][2], big_endian, p + 12);
    PutFloat(99.f, big_endian, p + 16);
  }
  c.msg.data = ByteView(c.data);
  return c;
}

const std::vector<std::array<float, 3>> kSix = {
    {1, 2, 3}, {4, 5, 6}, {7, 8, 9}, {-1, -2, -3}, {0.5f, 0.25f, 0.125f}, {10, 20, 30}};

class CloudOrder : public ::testing::TestWithParam<bool> {};

TEST_P(CloudOrder, OrganizedAndUnorganizedInPixelOrder) {
  for (const std::uint32_t width : {6u, 3u, 2u}) {  // 6 x 1 unorganized, 3 x 2, 2 x 3
    TestCloud c = MakeCloud(kSix, width, GetParam());
    std::vector<float> xyz;
    std::string detail;
    ASSERT_EQ(PointsFromPointCloud2(c.msg, 100, &xyz, &detail), Ros2Reject::kNone) << detail;
    ASSERT_EQ(xyz.size(), 18u);
    for (std::size_t i = 0; i < 6; ++i) {
      for (int a = 0; a < 3; ++a) EXPECT_EQ(xyz[3 * i + a], kSix[i][a]) << width << " " << i;
    }
  }
}

TEST_P(CloudOrder, NonFiniteCoordinatesAreNoReturn) {
  auto points = kSix;
  points[1][2] = NAN;
  points[3][0] = INFINITY;
  points[5][1] = -INFINITY;
  TestCloud c = MakeCloud(points, 3, GetParam());
  std::vector<float> xyz;
  ASSERT_EQ(PointsFromPointCloud2(c.msg, 6, &xyz), Ros2Reject::kNone);
  for (const std::size_t i : {1u, 3u, 5u}) {
    for (int a = 0; a < 3; ++a) EXPECT_TRUE(std::isnan(xyz[3 * i + a])) << i;
  }
  EXPECT_EQ(xyz[0], 1.f);
  EXPECT_EQ(xyz[3 * 4 + 2], 0.125f);
}

INSTANTIATE_TEST_SUITE_P(LittleAndBigEndian, CloudOrder, ::testing::Bool(), [](const auto& info) {
  return info.param ? "BigEndian" : "LittleEndian";
});

Ros2Reject Convert(const PointCloud2& msg, std::string* detail, std::size_t max = 1000) {
  std::vector<float> xyz = {1, 2, 3};
  const Ros2Reject r = PointsFromPointCloud2(msg, max, &xyz, detail);
  if (r != Ros2Reject::kNone) {
    EXPECT_TRUE(xyz.empty());
  }
  return r;
}

TEST(PointCloud2RejectTest, EveryReasonWithItsDetail) {
  TestCloud c = MakeCloud(kSix, 3, false);
  std::string detail;
  PointCloud2 m = c.msg;
  m.fields.erase(m.fields.begin() + 3);  // y
  EXPECT_EQ(Convert(m, &detail), Ros2Reject::kFieldsMissing);
  EXPECT_THAT(detail, HasSubstr("no field 'y'"));

  m = c.msg;
  m.fields[2].datatype = PointField::FLOAT64;  // x
  EXPECT_EQ(Convert(m, &detail), Ros2Reject::kFieldType);
  EXPECT_THAT(detail, HasSubstr("field 'x' is FLOAT64 (8), needs FLOAT32 (7)"));
  m.fields[2].datatype = PointField::INT16;
  EXPECT_EQ(Convert(m, &detail), Ros2Reject::kFieldType);

  m = c.msg;
  m.point_step = 15;  // z at 12..16
  EXPECT_EQ(Convert(m, &detail), Ros2Reject::kPointStep);
  EXPECT_THAT(detail, HasSubstr("point_step 15 ends before field 'z'"));
  m.fields[1].offset = 0xFFFFFFFE;  // no overflow into a small end
  m.point_step = 20;
  EXPECT_EQ(Convert(m, &detail), Ros2Reject::kPointStep);

  m = c.msg;
  m.row_step = 59;  // < 3 x 20
  EXPECT_EQ(Convert(m, &detail), Ros2Reject::kDataShort);
  EXPECT_THAT(detail, HasSubstr("row_step 59 < width 3 x point_step 20"));

  m = c.msg;
  m.data.size -= 1;
  EXPECT_EQ(Convert(m, &detail), Ros2Reject::kDataShort);
  EXPECT_THAT(detail, HasSubstr("data holds 131 bytes"));

  m = c.msg;
  EXPECT_EQ(Convert(m, &detail, 5), Ros2Reject::kTooLarge);
  EXPECT_THAT(detail, HasSubstr("3 x 2 points, at most 5"));
  m.width = 0xFFFFFFFF, m.height = 0xFFFFFFFF;  // 2^64 - ... points: no overflow
  EXPECT_EQ(Convert(m, &detail, 1u << 30), Ros2Reject::kTooLarge);

  m = c.msg;
  m.width = 0;
  EXPECT_EQ(Convert(m, nullptr), Ros2Reject::kNone);  // empty, and detail is optional

  for (const auto r : {Ros2Reject::kFieldsMissing, Ros2Reject::kFieldType, Ros2Reject::kPointStep,
                       Ros2Reject::kDataShort, Ros2Reject::kTooLarge, Ros2Reject::kEncoding,
                       Ros2Reject::kCameraInfo}) {
    EXPECT_STRNE(Ros2RejectName(r), "none");
  }
  EXPECT_STREQ(Ros2RejectName(Ros2Reject::kFieldsMissing), "fields_missing");
  EXPECT_STREQ(Ros2RejectName(Ros2Reject::kDataShort), "data_short");
  EXPECT_STREQ(Ros2RejectName(Ros2Reject::kCameraInfo), "camera_info");
}

// A width x height depth image whose pixel (u, v) is depth(u, v) metres.
struct TestDepth {
  Image image;
  CameraInfo info;
  Bytes data;
};
template <class Depth>
TestDepth MakeDepth(const std::string& encoding, std::uint32_t width, std::uint32_t height,
                    bool big_endian, Depth depth_m) {
  TestDepth d;
  const std::uint32_t bytes = encoding == "16UC1" ? 2 : 4;
  d.image.encoding = encoding;
  d.image.width = width, d.image.height = height;
  d.image.step = width * bytes + 2;  // padded rows
  d.image.is_bigendian = big_endian ? 1 : 0;
  d.data.assign(std::size_t{d.image.step} * height, 0x5A);
  for (std::uint32_t v = 0; v < height; ++v) {
    for (std::uint32_t u = 0; u < width; ++u) {
      std::uint8_t* p = d.data.data() + v * d.image.step + u * bytes;
      const double z = depth_m(u, v);
      if (bytes == 2) {
        const auto mm = static_cast<std::uint16_t>(std::lround(z * 1000));
        p[big_endian ? 0 : 1] = static_cast<std::uint8_t>(mm >> 8);
        p[big_endian ? 1 : 0] = static_cast<std::uint8_t>(mm & 0xFF);
      } else {
        PutFloat(static_cast<float>(z), big_endian, p);
      }
    }
  }
  d.image.data = ByteView(d.data);
  d.info.width = width, d.info.height = height;
  d.info.k = {50.0, 0, 3.5, 0, 40.0, 2.5, 0, 0, 1};
  return d;
}

double Ramp(std::uint32_t u, std::uint32_t v) {
  return u == 2 && v == 2 ? 0.0 : 1.0 + 0.1 * u + 0.01 * v;
}

struct DepthCase {
  const char* encoding;
  bool big_endian;
  int stride;
};
class DepthTest : public ::testing::TestWithParam<DepthCase> {};

TEST_P(DepthTest, BackProjectsEveryStridedPixel) {
  const DepthCase c = GetParam();
  TestDepth d = MakeDepth(c.encoding, 7, 5, c.big_endian, Ramp);
  std::vector<float> xyz;
  std::string detail;
  ASSERT_EQ(PointsFromDepthImage(d.image, d.info, c.stride, 1000, &xyz, &detail), Ros2Reject::kNone)
      << detail;
  const std::uint32_t cols = StridedSize(7, c.stride), rows = StridedSize(5, c.stride);
  ASSERT_EQ(xyz.size(), 3u * cols * rows);
  const double tolerance = std::string(c.encoding) == "16UC1" ? 1e-6 : 1e-6;
  for (std::uint32_t r = 0; r < rows; ++r) {
    for (std::uint32_t col = 0; col < cols; ++col) {
      const std::uint32_t u = col * c.stride, v = r * c.stride;
      const float* p = &xyz[3 * (r * cols + col)];
      const double z = std::string(c.encoding) == "16UC1" ? std::round(Ramp(u, v) * 1000) / 1000
                                                          : static_cast<float>(Ramp(u, v));
      if (z == 0) {
        EXPECT_TRUE(std::isnan(p[0]) && std::isnan(p[1]) && std::isnan(p[2])) << u << "," << v;
        continue;
      }
      EXPECT_NEAR(p[2], z, tolerance) << u << "," << v;
      EXPECT_NEAR(p[0], (u - 3.5) * z / 50.0, 1e-6) << u << "," << v;
      EXPECT_NEAR(p[1], (v - 2.5) * z / 40.0, 1e-6) << u << "," << v;
    }
  }
}

INSTANTIATE_TEST_SUITE_P(
    Encodings, DepthTest,
    ::testing::Values(DepthCase{"16UC1", false, 1}, DepthCase{"16UC1", true, 1},
                      DepthCase{"16UC1", false, 2}, DepthCase{"32FC1", false, 1},
                      DepthCase{"32FC1", true, 3}, DepthCase{"32FC1", false, 2}),
    [](const auto& info) {
      return std::string("E") + info.param.encoding +
             (info.param.big_endian ? "BigEndian" : "LittleEndian") + "Stride" +
             std::to_string(info.param.stride);
    });

TEST(DepthImageTest, NonFiniteAndNegativeFloatDepthsAreNoReturn) {
  TestDepth d = MakeDepth("32FC1", 4, 1, false, [](std::uint32_t u, std::uint32_t) {
    return u == 0 ? NAN : u == 1 ? INFINITY : u == 2 ? -1.0 : 2.0;
  });
  std::vector<float> xyz;
  ASSERT_EQ(PointsFromDepthImage(d.image, d.info, 1, 10, &xyz), Ros2Reject::kNone);
  for (int i = 0; i < 9; ++i) EXPECT_TRUE(std::isnan(xyz[i])) << i;
  EXPECT_EQ(xyz[11], 2.f);
}

TEST(DepthImageTest, EveryReasonWithItsDetail) {
  TestDepth d = MakeDepth("16UC1", 7, 5, false, Ramp);
  std::vector<float> xyz = {1};
  std::string detail;
  Image image = d.image;
  image.encoding = "rgb8";
  EXPECT_EQ(PointsFromDepthImage(image, d.info, 1, 100, &xyz, &detail), Ros2Reject::kEncoding);
  EXPECT_THAT(detail, HasSubstr("'rgb8' is not a depth image"));
  EXPECT_TRUE(xyz.empty());

  CameraInfo info = d.info;
  info.k[4] = 0;
  EXPECT_EQ(PointsFromDepthImage(d.image, info, 1, 100, &xyz, &detail), Ros2Reject::kCameraInfo);
  EXPECT_THAT(detail, HasSubstr("focal lengths must be non-zero"));
  info = d.info;
  info.width = 640;
  EXPECT_EQ(PointsFromDepthImage(d.image, info, 1, 100, &xyz, &detail), Ros2Reject::kCameraInfo);
  EXPECT_THAT(detail, HasSubstr("CameraInfo is 640 x 5, the image 7 x 5"));

  EXPECT_EQ(PointsFromDepthImage(d.image, d.info, 1, 34, &xyz, &detail), Ros2Reject::kTooLarge);
  EXPECT_EQ(PointsFromDepthImage(d.image, d.info, 2, 12, &xyz, &detail), Ros2Reject::kNone);

  image = d.image;
  image.step = 13;
  EXPECT_EQ(PointsFromDepthImage(image, d.info, 1, 100, &xyz, &detail), Ros2Reject::kDataShort);
  EXPECT_THAT(detail, HasSubstr("step 13 < width 7 x 2 bytes"));
  image = d.image;
  image.data.size = 10;
  EXPECT_EQ(PointsFromDepthImage(image, d.info, 1, 100, &xyz, &detail), Ros2Reject::kDataShort);
  EXPECT_THAT(detail, HasSubstr("data holds 10 bytes"));

  EXPECT_THROW((void)PointsFromDepthImage(d.image, d.info, 0, 100, &xyz), std::invalid_argument);
}

}  // namespace
}  // namespace fusion::ros2
