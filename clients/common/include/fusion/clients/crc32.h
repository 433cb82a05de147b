// CRC-32 (IEEE 802.3, the zlib/PNG polynomial) for framing records.
#pragma once

#include <cstddef>
#include <cstdint>

namespace fusion::clients {

// CRC-32 of `size` bytes, continuing from `crc` (0 to start), e.g. Crc32("123456789") =
// 0xCBF43926.
[[nodiscard]] std::uint32_t Crc32(const void* data, std::size_t size, std::uint32_t crc = 0);

}  // namespace fusion::clients
