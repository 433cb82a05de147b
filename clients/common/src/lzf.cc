#include "fusion/clients/lzf.h"

#include <cstdint>
#include <cstring>

namespace fusion::clients {

// LZF: a control byte c < 32 starts a literal run of c + 1 bytes; otherwise the top three
// bits are a match length (7 = one more length byte follows), the low five bits and the next
// byte a back-reference distance - 1. Written from the format description, bounds-checked.
std::size_t LzfDecompress(const void* in, std::size_t in_size, void* out, std::size_t out_size) {
  const auto* ip = static_cast<const std::uint8_t*>(in);
  const std::uint8_t* const in_end = ip + in_size;
  auto* op = static_cast<std::uint8_t*>(out);
  std::uint8_t* const out_start = op;
  std::uint8_t* const out_end = op + out_size;
  while (ip < in_end) {
    std::size_t ctrl = *ip++;
    if (ctrl < 32) {
      const std::size_t length = ctrl + 1;
      if (static_cast<std::size_t>(in_end - ip) < length) return 0;
      if (static_cast<std::size_t>(out_end - op) < length) return 0;
      std::memcpy(op, ip, length);
      op += length;
      ip += length;
    } else {
      std::size_t length = ctrl >> 5;
      if (length == 7) {
        if (ip >= in_end) return 0;
        length += *ip++;
      }
      length += 2;
      if (ip >= in_end) return 0;
      const std::size_t distance = ((ctrl & 0x1Fu) << 8) + *ip++ + 1;
      if (distance > static_cast<std::size_t>(op - out_start)) return 0;
      if (static_cast<std::size_t>(out_end - op) < length) return 0;
      const std::uint8_t* ref = op - distance;
      // Byte by byte: the reference may overlap the output (run-length style).
      for (std::size_t i = 0; i < length; ++i) *op++ = *ref++;
    }
  }
  return static_cast<std::size_t>(op - out_start);
}

}  // namespace fusion::clients
