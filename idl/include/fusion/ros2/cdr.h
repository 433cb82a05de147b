// XCDR1 (plain CDR, what ROS 2 puts on DDS and in its bags) of the messages in ros2/messages.h.
//
// A serialized message starts with the 4-byte encapsulation header: 0x00 0x00 = CDR big-endian,
// 0x00 0x01 = CDR little-endian, then two option bytes (ignored). Every primitive is aligned to
// its own size (at most 8) relative to the byte after that header; strings are a uint32 length
// that counts the terminating NUL, then the bytes; sequences a uint32 element count, then the
// elements; fixed arrays just their elements. Bytes after the message (padding) are ignored.
//
// Decoding checks every length against the buffer and never reads outside it. A decoded
// message's `data` points into the buffer (no copy). Errors name the field and the byte offset
// from the start of the buffer (header included):
//   "PointCloud2.fields[2].name: string runs past the end at byte 812"
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "fusion/ros2/messages.h"

namespace fusion::ros2 {

// The outcome of a decode: OK, or what broke and where.
struct [[nodiscard]] CdrResult {
  std::string error;  // empty when OK
  [[nodiscard]] bool ok() const { return error.empty(); }
};

CdrResult DecodeCdr(ByteView serialized, PointCloud2* message);
CdrResult DecodeCdr(ByteView serialized, Image* message);
CdrResult DecodeCdr(ByteView serialized, CameraInfo* message);
CdrResult DecodeCdr(ByteView serialized, TFMessage* message);
CdrResult DecodeCdr(ByteView serialized, TransformStamped* message);
CdrResult DecodeCdr(ByteView serialized, Header* message);

enum class CdrEndian { kLittle, kBig };

// The serialized message (encapsulation header first). Bag writers of tests, seed corpora.
std::vector<std::uint8_t> EncodeCdr(const PointCloud2& message,
                                    CdrEndian endian = CdrEndian::kLittle);
std::vector<std::uint8_t> EncodeCdr(const Image& message, CdrEndian endian = CdrEndian::kLittle);
std::vector<std::uint8_t> EncodeCdr(const CameraInfo& message,
                                    CdrEndian endian = CdrEndian::kLittle);
std::vector<std::uint8_t> EncodeCdr(const TFMessage& message,
                                    CdrEndian endian = CdrEndian::kLittle);
std::vector<std::uint8_t> EncodeCdr(const TransformStamped& message,
                                    CdrEndian endian = CdrEndian::kLittle);
std::vector<std::uint8_t> EncodeCdr(const Header& message, CdrEndian endian = CdrEndian::kLittle);

}  // namespace fusion::ros2
