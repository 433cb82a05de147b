#include <cstring>

#include "common.h"
#include "fusion/clients/crc32.h"
#include "fusion/clients/recording.h"

namespace fusion::fuzz {
namespace {

std::uint32_t Le32(const std::string& b, std::size_t at) {
  std::uint32_t v = 0;
  for (int i = 3; i >= 0; --i) v = (v << 8) | static_cast<std::uint8_t>(b[at + i]);
  return v;
}
std::uint32_t Be32(const std::string& b, std::size_t at) {
  std::uint32_t v = 0;
  for (int i = 0; i < 4; ++i) v = (v << 8) | static_cast<std::uint8_t>(b[at + i]);
  return v;
}
void PutLe32(std::string* b, std::size_t at, std::uint32_t v) {
  for (int i = 0; i < 4; ++i) (*b)[at + i] = static_cast<char>(v >> (8 * i));
}
void PutBe32(std::string* b, std::size_t at, std::uint32_t v) {
  for (int i = 0; i < 4; ++i) (*b)[at + i] = static_cast<char>(v >> (24 - 8 * i));
}

}  // namespace

void FixRecordingCrcs(std::string* bytes) {
  // A closed recording ends in a 16-byte footer, not a frame.
  std::size_t end = bytes->size();
  if (end >= 16 && bytes->compare(end - 8, 8, clients::kFooterMagic, 8) == 0) end -= 16;
  std::size_t at = 0;
  while (end - at >= 8) {
    const std::uint64_t length = Le32(*bytes, at);
    if (length > end - at - 8) return;
    PutLe32(bytes, at + 4, clients::Crc32(bytes->data() + at + 8, length));
    at += 8 + length;
  }
}

void FixPngCrcs(std::string* bytes, std::size_t png_start) {
  std::size_t at = png_start + 8;  // after the signature
  while (at <= bytes->size() && bytes->size() - at >= 12) {
    const std::uint64_t length = Be32(*bytes, at);
    if (length > bytes->size() - at - 12) return;
    PutBe32(bytes, at + 8 + length, clients::Crc32(bytes->data() + at + 4, 4 + length));
    at += 12 + length;
  }
}

}  // namespace fusion::fuzz
