// 16-bit grayscale PNG reading (TUM depth images) through libpng, bounded before allocating.
#include <png.h>

#include <cerrno>
#include <cstdio>
#include <cstring>

#include "fusion/clients/importers.h"

namespace fusion::clients {

namespace {
struct PngReadState {
  png_structp png = nullptr;
  png_infop info = nullptr;
  std::FILE* file = nullptr;
  std::string error;
  // Kept here, not in locals of ReadPng16: locals changed after setjmp are indeterminate after
  // libpng's longjmp.
  std::vector<png_bytep> rows;
  ~PngReadState() {
    png_destroy_read_struct(png ? &png : nullptr, info ? &info : nullptr, nullptr);
    if (file) std::fclose(file);
  }
};

// A PNG header may claim up to 10^6 x 10^6 pixels (libpng's default limits) before any of them
// is read: allocate only for plausible depth images (4096 x 4096; a TUM frame is 640 x 480).
constexpr std::uint64_t kMaxPngPixels = std::uint64_t{1} << 24;

void PngError(png_structp png, png_const_charp message) {
  static_cast<PngReadState*>(png_get_error_ptr(png))->error = message;
  png_longjmp(png, 1);
}
void PngWarning(png_structp, png_const_charp) {}
}  // namespace

Status ReadPng16(const std::string& path, std::uint32_t* width, std::uint32_t* height,
                 std::vector<std::uint16_t>* values) {
  PngReadState state;
  state.file = std::fopen(path.c_str(), "rb");
  if (state.file == nullptr)
    return Status::Error("cannot open " + path + ": " + std::strerror(errno));
  unsigned char signature[8];
  if (std::fread(signature, 1, 8, state.file) != 8 || png_sig_cmp(signature, 0, 8) != 0) {
    return Status::Error(path + ": not a PNG file");
  }
  state.png = png_create_read_struct(PNG_LIBPNG_VER_STRING, &state, PngError, PngWarning);
  if (state.png == nullptr) return Status::Error("png_create_read_struct failed");
  state.info = png_create_info_struct(state.png);
  if (state.info == nullptr) return Status::Error("png_create_info_struct failed");
  if (setjmp(png_jmpbuf(state.png))) return Status::Error(path + ": corrupt PNG: " + state.error);
  png_init_io(state.png, state.file);
  png_set_sig_bytes(state.png, 8);
  png_read_info(state.png, state.info);
  const png_uint_32 w = png_get_image_width(state.png, state.info);
  const png_uint_32 h = png_get_image_height(state.png, state.info);
  const int depth = png_get_bit_depth(state.png, state.info);
  const int color = png_get_color_type(state.png, state.info);
  if (depth != 16 || color != PNG_COLOR_TYPE_GRAY) {
    return Status::Error(path + ": expected a 16-bit grayscale depth PNG, got bit depth " +
                         std::to_string(depth) + ", colour type " + std::to_string(color));
  }
  if (std::uint64_t{w} * h > kMaxPngPixels) {
    return Status::Error(path + ": " + std::to_string(w) + " x " + std::to_string(h) +
                         " pixels is more than the " + std::to_string(kMaxPngPixels) +
                         " a depth image may have");
  }
  png_set_swap(state.png);  // PNG stores 16-bit samples big-endian
  png_read_update_info(state.png, state.info);
  values->assign(static_cast<std::size_t>(w) * h, 0);
  state.rows.resize(h);
  for (png_uint_32 y = 0; y < h; ++y) {
    state.rows[y] = reinterpret_cast<png_bytep>(values->data() + static_cast<std::size_t>(y) * w);
  }
  png_read_image(state.png, state.rows.data());
  png_read_end(state.png, nullptr);
  *width = w;
  *height = h;
  return Status::Ok();
}

}  // namespace fusion::clients
