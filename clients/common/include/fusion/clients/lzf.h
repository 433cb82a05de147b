// LZF decompression (the format of PCD's binary_compressed data, Marc Lehmann's liblzf).
#pragma once

#include <cstddef>

namespace fusion::clients {

// Decompresses `in_size` bytes into `out` (capacity `out_size`). Returns the number of bytes
// written, or 0 when the input is corrupt or does not fit (never reads or writes out of bounds).
[[nodiscard]] std::size_t LzfDecompress(const void* in, std::size_t in_size, void* out,
                                        std::size_t out_size);

}  // namespace fusion::clients
