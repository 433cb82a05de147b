// XCDR1 of the ROS 2 messages (fusion/ros2/cdr.h): round trips of every message in both byte
// orders, a big-endian buffer built by hand byte for byte, and every way a buffer can be cut
// or lie about its lengths reported with the field, never a crash.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cstring>

#include "fusion/ros2/cdr.h"

namespace fusion::ros2 {
namespace {

using ::testing::HasSubstr;
using Bytes = std::vector<std::uint8_t>;

PointCloud2 SampleCloud(const Bytes& data) {
  PointCloud2 m;
  m.header.stamp = {1700000000, 123456789};
  m.header.frame_id = "lidar";
  m.height = 1;
  m.width = 2;
  m.fields = {{"x", 0, PointField::FLOAT32, 1},
              {"y", 4, PointField::FLOAT32, 1},
              {"z", 8, PointField::FLOAT32, 1},
              {"intensity", 12, PointField::UINT16, 1}};
  m.is_bigendian = false;
  m.point_step = 16;
  m.row_step = 32;
  m.data = ByteView(data);
  m.is_dense = true;
  return m;
}

void ExpectSame(const Header& a, const Header& b) {
  EXPECT_EQ(a.stamp.sec, b.stamp.sec);
  EXPECT_EQ(a.stamp.nanosec, b.stamp.nanosec);
  EXPECT_EQ(a.frame_id, b.frame_id);
}

class CdrRoundTrip : public ::testing::TestWithParam<CdrEndian> {};

TEST_P(CdrRoundTrip, PointCloud2) {
  Bytes data(32);
  for (std::size_t i = 0; i < data.size(); ++i) data[i] = static_cast<std::uint8_t>(3 * i + 1);
  const PointCloud2 in = SampleCloud(data);
  const Bytes wire = EncodeCdr(in, GetParam());
  EXPECT_EQ(wire[1], GetParam() == CdrEndian::kLittle ? 1 : 0);
  PointCloud2 out;
  ASSERT_TRUE(DecodeCdr(ByteView(wire), &out).ok());
  ExpectSame(in.header, out.header);
  EXPECT_EQ(out.height, 1u);
  EXPECT_EQ(out.width, 2u);
  ASSERT_EQ(out.fields.size(), 4u);
  for (std::size_t i = 0; i < 4; ++i) {
    EXPECT_EQ(out.fields[i].name, in.fields[i].name);
    EXPECT_EQ(out.fields[i].offset, in.fields[i].offset);
    EXPECT_EQ(out.fields[i].datatype, in.fields[i].datatype);
    EXPECT_EQ(out.fields[i].count, in.fields[i].count);
  }
  EXPECT_EQ(out.point_step, 16u);
  EXPECT_EQ(out.row_step, 32u);
  EXPECT_TRUE(out.is_dense);
  EXPECT_FALSE(out.is_bigendian);
  ASSERT_EQ(out.data.size, data.size());
  EXPECT_TRUE(std::equal(data.begin(), data.end(), out.data.begin()));
  // No copy: the view points into the serialized buffer.
  EXPECT_GE(out.data.data, wire.data());
  EXPECT_LE(out.data.end(), wire.data() + wire.size());
}

TEST_P(CdrRoundTrip, Image) {
  const Bytes data = {1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12};
  Image in;
  in.header = {{-5, 999999999}, "camera_depth_optical_frame"};
  in.height = 2, in.width = 3, in.encoding = "16UC1", in.is_bigendian = 1, in.step = 6;
  in.data = ByteView(data);
  const Bytes wire = EncodeCdr(in, GetParam());
  Image out;
  ASSERT_TRUE(DecodeCdr(ByteView(wire), &out).ok());
  ExpectSame(in.header, out.header);
  EXPECT_EQ(out.height, 2u);
  EXPECT_EQ(out.width, 3u);
  EXPECT_EQ(out.encoding, "16UC1");
  EXPECT_EQ(out.is_bigendian, 1);
  EXPECT_EQ(out.step, 6u);
  EXPECT_EQ(Bytes(out.data.begin(), out.data.end()), data);
}

TEST_P(CdrRoundTrip, CameraInfo) {
  CameraInfo in;
  in.header = {{12, 34}, "cam"};
  in.height = 480, in.width = 640, in.distortion_model = "plumb_bob";
  in.d = {0.1, -0.2, 0.001, 0.002, 0.03};
  for (int i = 0; i < 9; ++i) in.k[i] = 100.0 + i, in.r[i] = i * 0.5;
  for (int i = 0; i < 12; ++i) in.p[i] = -1.0 * i;
  in.binning_x = 2, in.binning_y = 3;
  in.roi = {10, 20, 30, 40, true};
  const Bytes wire = EncodeCdr(in, GetParam());
  CameraInfo out;
  ASSERT_TRUE(DecodeCdr(ByteView(wire), &out).ok());
  ExpectSame(in.header, out.header);
  EXPECT_EQ(out.height, 480u);
  EXPECT_EQ(out.width, 640u);
  EXPECT_EQ(out.distortion_model, "plumb_bob");
  EXPECT_EQ(out.d, in.d);
  EXPECT_EQ(out.k, in.k);
  EXPECT_EQ(out.r, in.r);
  EXPECT_EQ(out.p, in.p);
  EXPECT_EQ(out.binning_x, 2u);
  EXPECT_EQ(out.binning_y, 3u);
  EXPECT_EQ(out.roi.x_offset, 10u);
  EXPECT_EQ(out.roi.y_offset, 20u);
  EXPECT_EQ(out.roi.height, 30u);
  EXPECT_EQ(out.roi.width, 40u);
  EXPECT_TRUE(out.roi.do_rectify);
}

TEST_P(CdrRoundTrip, TFMessageAndTransformStamped) {
  TFMessage in;
  for (int i = 0; i < 3; ++i) {
    TransformStamped t;
    t.header = {{100 + i, 5u * i}, i == 0 ? "map" : "odom"};
    t.child_frame_id = "base_link_" + std::to_string(i);
    t.transform.translation = {1.0 + i, -2.0, 0.5};
    t.transform.rotation = {0.0, 0.0, std::sqrt(0.5), std::sqrt(0.5)};
    in.transforms.push_back(t);
  }
  const Bytes wire = EncodeCdr(in, GetParam());
  TFMessage out;
  ASSERT_TRUE(DecodeCdr(ByteView(wire), &out).ok());
  ASSERT_EQ(out.transforms.size(), 3u);
  for (int i = 0; i < 3; ++i) {
    const TransformStamped& a = in.transforms[i];
    const TransformStamped& b = out.transforms[i];
    ExpectSame(a.header, b.header);
    EXPECT_EQ(a.child_frame_id, b.child_frame_id);
    EXPECT_EQ(a.transform.translation.x, b.transform.translation.x);
    EXPECT_EQ(a.transform.translation.y, b.transform.translation.y);
    EXPECT_EQ(a.transform.translation.z, b.transform.translation.z);
    EXPECT_EQ(a.transform.rotation.z, b.transform.rotation.z);
    EXPECT_EQ(a.transform.rotation.w, b.transform.rotation.w);
  }
  TransformStamped one;
  ASSERT_TRUE(DecodeCdr(ByteView(EncodeCdr(in.transforms[1], GetParam())), &one).ok());
  EXPECT_EQ(one.child_frame_id, "base_link_1");
  EXPECT_EQ(one.transform.translation.x, 2.0);
  Header header;
  ASSERT_TRUE(DecodeCdr(ByteView(EncodeCdr(in.transforms[2].header, GetParam())), &header).ok());
  ExpectSame(header, in.transforms[2].header);
}

INSTANTIATE_TEST_SUITE_P(BothOrders, CdrRoundTrip,
                         ::testing::Values(CdrEndian::kLittle, CdrEndian::kBig),
                         [](const auto& info) {
                           return info.param == CdrEndian::kLittle ? "LittleEndian" : "BigEndian";
                         });

// Appends big-endian bytes of `value` after padding to its alignment (relative to byte 4).
class BigEndianBuffer {
 public:
  BigEndianBuffer() : bytes_{0x00, 0x00, 0x00, 0x00} {}
  void U8(std::uint8_t v) { bytes_.push_back(v); }
  void U32(std::uint32_t v) {
    Pad(4);
    for (int s = 24; s >= 0; s -= 8) bytes_.push_back(static_cast<std::uint8_t>(v >> s));
  }
  void F64(double d) {
    Pad(8);
    std::uint64_t v;
    std::memcpy(&v, &d, 8);
    for (int s = 56; s >= 0; s -= 8) bytes_.push_back(static_cast<std::uint8_t>(v >> s));
  }
  void Str(const std::string& s) {
    U32(static_cast<std::uint32_t>(s.size() + 1));
    bytes_.insert(bytes_.end(), s.begin(), s.end());
    bytes_.push_back(0);
  }
  const Bytes& bytes() const { return bytes_; }

 private:
  void Pad(std::size_t n) {
    while ((bytes_.size() - 4) % n != 0) bytes_.push_back(0xEE);  // padding content is ignored
  }
  Bytes bytes_;
};

TEST(CdrDecodeTest, HandBuiltBigEndianPointCloud2) {
  BigEndianBuffer b;
  b.U32(7);          // stamp.sec
  b.U32(500000000);  // stamp.nanosec
  b.Str("sensor");   // frame_id: length 7 at byte 12, then 7 bytes -> 19
  b.U32(2);          // height (padded to byte 20)
  b.U32(3);          // width
  b.U32(1);          // one field
  b.Str("z");
  b.U32(8);  // offset (after 2 padding bytes)
  b.U8(PointField::FLOAT32);
  b.U32(1);   // count
  b.U8(1);    // is_bigendian
  b.U32(12);  // point_step
  b.U32(36);  // row_step
  b.U32(3);   // data: 3 bytes
  b.U8(0xAA), b.U8(0xBB), b.U8(0xCC);
  b.U8(0);  // is_dense
  PointCloud2 m;
  const CdrResult r = DecodeCdr(ByteView(b.bytes()), &m);
  ASSERT_TRUE(r.ok()) << r.error;
  EXPECT_EQ(m.header.stamp.sec, 7);
  EXPECT_EQ(m.header.stamp.nanosec, 500000000u);
  EXPECT_DOUBLE_EQ(m.header.stamp.seconds(), 7.5);
  EXPECT_EQ(m.header.frame_id, "sensor");
  EXPECT_EQ(m.height, 2u);
  EXPECT_EQ(m.width, 3u);
  ASSERT_EQ(m.fields.size(), 1u);
  EXPECT_EQ(m.fields[0].name, "z");
  EXPECT_EQ(m.fields[0].offset, 8u);
  EXPECT_EQ(m.fields[0].datatype, PointField::FLOAT32);
  EXPECT_TRUE(m.is_bigendian);
  EXPECT_EQ(m.point_step, 12u);
  EXPECT_EQ(m.row_step, 36u);
  ASSERT_EQ(m.data.size, 3u);
  EXPECT_EQ(m.data[2], 0xCC);
  EXPECT_FALSE(m.is_dense);
  // Our own big-endian encoder writes the same bytes except the padding (zeros there).
  Bytes ours = EncodeCdr(m, CdrEndian::kBig);
  ASSERT_EQ(ours.size(), b.bytes().size());
  for (std::size_t i = 0; i < ours.size(); ++i) {
    if (b.bytes()[i] != 0xEE) {
      EXPECT_EQ(ours[i], b.bytes()[i]) << "byte " << i;
    }
  }
}

TEST(CdrDecodeTest, HandBuiltBigEndianCameraInfoAlignsDoublesToEight) {
  BigEndianBuffer b;
  b.U32(1), b.U32(2), b.Str("c");  // header: ends at byte 4 + 14 = 18
  b.U32(4), b.U32(6);              // height, width
  b.Str("plumb_bob");              // ends at an odd offset
  b.U32(1);
  b.F64(0.25);  // d[0], padded to 8
  for (int i = 0; i < 9; ++i) b.F64(i);
  for (int i = 0; i < 9; ++i) b.F64(0);
  for (int i = 0; i < 12; ++i) b.F64(0);
  b.U32(1), b.U32(1);
  b.U32(0), b.U32(0), b.U32(0), b.U32(0), b.U8(0);
  CameraInfo m;
  const CdrResult r = DecodeCdr(ByteView(b.bytes()), &m);
  ASSERT_TRUE(r.ok()) << r.error;
  EXPECT_EQ(m.width, 6u);
  ASSERT_EQ(m.d.size(), 1u);
  EXPECT_EQ(m.d[0], 0.25);
  EXPECT_EQ(m.k[8], 8.0);
}

std::string DecodeError(const Bytes& wire) {
  PointCloud2 m;
  return DecodeCdr(ByteView(wire), &m).error;
}

TEST(CdrDecodeTest, EveryTruncationIsAnErrorNamingAField) {
  const Bytes data(32, 7);
  const Bytes wire = EncodeCdr(SampleCloud(data));
  for (std::size_t n = 0; n + 1 < wire.size(); ++n) {
    const Bytes cut(wire.begin(), wire.begin() + n);
    const std::string error = DecodeError(cut);
    ASSERT_FALSE(error.empty()) << "cut at " << n;
    EXPECT_THAT(error, HasSubstr("PointCloud2")) << n;
    EXPECT_THAT(error, HasSubstr(" at byte ")) << n;
  }
  // The last byte (is_dense) alone missing.
  EXPECT_THAT(DecodeError(Bytes(wire.begin(), wire.end() - 1)),
              HasSubstr("PointCloud2.is_dense: value runs past the end"));
}

TEST(CdrDecodeTest, LengthsThatLieAreNamed) {
  const Bytes data(32, 7);
  const Bytes wire = EncodeCdr(SampleCloud(data));
  // Layout: header 4, stamp 8, frame_id "lidar" 4 + 6 -> 22, pad -> 24, height, width, count at
  // byte 4 + 28 = 32; fields[0].name length at 36.
  Bytes bad = wire;
  bad[36] = 0xFF, bad[37] = 0xFF;  // fields[0].name: 65535 bytes
  EXPECT_EQ(DecodeError(bad), "PointCloud2.fields[0].name: string runs past the end at byte 36");
  bad = wire;
  bad[32] = 0x00, bad[33] = 0x00, bad[34] = 0x00, bad[35] = 0x10;  // 2^28 fields
  EXPECT_THAT(DecodeError(bad), HasSubstr("PointCloud2.fields: sequence of 268435456 runs past"));
  bad = wire;
  bad[12] = 200;  // frame_id length
  EXPECT_EQ(DecodeError(bad), "PointCloud2.header.frame_id: string runs past the end at byte 12");
  bad = wire;
  bad[21] = 'x';  // frame_id's NUL
  EXPECT_THAT(DecodeError(bad), HasSubstr("header.frame_id: string lacks its NUL"));
  // The data length: 4 bytes before the 32 data bytes and the is_dense byte.
  bad = wire;
  const std::size_t data_length = wire.size() - 1 - 32 - 4;
  bad[data_length] = 34;  // 33 would still fit, leaving is_dense out
  EXPECT_THAT(DecodeError(bad), HasSubstr("PointCloud2.data: sequence of 34 runs past the end"));
  bad = wire;
  bad.back() = 2;
  EXPECT_THAT(DecodeError(bad), HasSubstr("PointCloud2.is_dense: boolean is 2"));
}

TEST(CdrDecodeTest, EncapsulationMustBeXcdr1) {
  EXPECT_THAT(DecodeError({}), HasSubstr("encapsulation header needs 4 bytes"));
  EXPECT_THAT(DecodeError({0x00, 0x07, 0, 0, 0, 0, 0, 0}),
              HasSubstr("encapsulation 0x0007 is not XCDR1"));
  EXPECT_THAT(DecodeError({0x00, 0x03, 0, 0}), HasSubstr("0x0003"));
  TFMessage tf;
  const CdrResult r = DecodeCdr(ByteView(Bytes{0x00, 0x01, 0, 0, 200, 0, 0, 0}), &tf);
  EXPECT_THAT(r.error, HasSubstr("TFMessage.transforms: sequence of 200 runs past the end"));
}

TEST(CdrDecodeTest, NestedErrorsNameTheElement) {
  TFMessage tf;
  tf.transforms.resize(2);
  tf.transforms[1].child_frame_id = "child";
  Bytes wire = EncodeCdr(tf);
  wire.resize(wire.size() - 8);  // rotation.w of the second transform
  TFMessage out;
  EXPECT_THAT(DecodeCdr(ByteView(wire), &out).error,
              HasSubstr("TFMessage.transforms[1].transform.rotation.w: value runs past the end"));
}

TEST(CdrDecodeTest, OwnedMessageOutlivesItsBuffer) {
  Owned<Image> owned;
  {
    const Bytes data = {9, 8, 7, 6};
    Image image;
    image.width = 2, image.height = 1, image.step = 4, image.encoding = "16UC1";
    image.data = ByteView(data);
    const Bytes wire = EncodeCdr(image);
    Image decoded;
    ASSERT_TRUE(DecodeCdr(ByteView(wire), &decoded).ok());
    owned = MakeOwned(decoded);
  }  // data and wire are gone
  const Owned<Image> copy = owned;
  EXPECT_EQ(copy.message.data.data, owned.bytes->data());
  ASSERT_EQ(copy.message.data.size, 4u);
  EXPECT_EQ(copy.message.data[0], 9);
  EXPECT_EQ(copy.message.data[3], 6);
  EXPECT_EQ(copy.message.encoding, "16UC1");
}

TEST(CdrDecodeTest, ZeroLengthStringIsEmpty) {
  BigEndianBuffer b;
  b.U32(0), b.U32(0), b.U32(0);  // stamp and frame_id of length 0
  Header h;
  ASSERT_TRUE(DecodeCdr(ByteView(b.bytes()), &h).ok());
  EXPECT_EQ(h.frame_id, "");
}

}  // namespace
}  // namespace fusion::ros2
