#include "fusion/clients/importers.h"

#include <fcntl.h>
#include <octomap/ScanGraph.h>
#include <png.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <csetjmp>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <limits>
#include <memory>
#include <sstream>

#include "fusion/clients/cli.h"
#include "fusion/clients/lzf.h"

namespace fusion::clients {

static_assert(__BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__,
              "xyz_f32le is written with memcpy: little-endian hosts only");

namespace {

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

bool EndsWith(const std::string& s, const std::string& suffix) {
  return s.size() >= suffix.size() &&
         s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

// Rotates v by the unit quaternion (x, y, z, w); `inverse` rotates by its conjugate.
void Rotate(const fusion::v1::RecordedPose& pose, bool inverse, const double v[3], double out[3]) {
  const double qx = inverse ? -pose.qx() : pose.qx(), qy = inverse ? -pose.qy() : pose.qy(),
               qz = inverse ? -pose.qz() : pose.qz(), qw = pose.qw();
  // t = 2 q_vec x v; v' = v + qw t + q_vec x t
  const double tx = 2 * (qy * v[2] - qz * v[1]);
  const double ty = 2 * (qz * v[0] - qx * v[2]);
  const double tz = 2 * (qx * v[1] - qy * v[0]);
  out[0] = v[0] + qw * tx + (qy * tz - qz * ty);
  out[1] = v[1] + qw * ty + (qz * tx - qx * tz);
  out[2] = v[2] + qw * tz + (qx * ty - qy * tx);
}

}  // namespace

void AppendPoint(float x, float y, float z, fusion::v1::RecordedCloud* cloud) {
  const float xyz[3] = {x, y, z};
  cloud->mutable_xyz_f32le()->append(reinterpret_cast<const char*>(xyz), sizeof xyz);
}

void GetPoint(const fusion::v1::RecordedCloud& cloud, std::size_t i, float xyz[3]) {
  std::memcpy(xyz, cloud.xyz_f32le().data() + 12 * i, 12);
}

double FractionBehindSensor(const fusion::v1::RecordedCloud& cloud) {
  const std::size_t n = cloud.xyz_f32le().size() / 12;
  std::size_t finite = 0, behind = 0;
  for (std::size_t i = 0; i < n; ++i) {
    float p[3];
    GetPoint(cloud, i, p);
    if (!std::isfinite(p[0]) || !std::isfinite(p[1]) || !std::isfinite(p[2])) continue;
    ++finite;
    if (p[2] < 0) ++behind;
  }
  return finite ? static_cast<double>(behind) / static_cast<double>(finite) : 0.0;
}

void SetIdentity(const std::string& sensor_id, std::uint64_t sequence_number, double stamp_s,
                 const std::string& origin, fusion::v1::RecordedCloud* cloud) {
  cloud->set_sensor_id(sensor_id);
  cloud->set_sequence_number(sequence_number);
  *cloud->mutable_stamp() = TimeFromSeconds(stamp_s);
  cloud->set_receive_time_unix_ns(static_cast<std::int64_t>(cloud->stamp().sec()) * 1000000000 +
                                  cloud->stamp().nanosec());
  cloud->set_origin(origin);
}

// ---------------------------------------------------------------------------------------------
// PNG

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

// ---------------------------------------------------------------------------------------------
// TUM

Status ImportTum(const TumOptions& options, const CloudSink& sink) {
  if (options.stride == 0) return Status::Error("--stride must be at least 1");
  if (!(options.fx_px > 0 && options.fy_px > 0 && options.depth_scale > 0)) {
    return Status::Error("focal lengths and depth scale must be positive");
  }
  const std::string list_path = options.directory + "/" + options.groundtruth;
  std::ifstream list(list_path);
  if (!list) return Status::Error("cannot open " + list_path + ": " + std::strerror(errno));
  std::string line;
  std::uint64_t line_number = 0, frames = 0;
  while (std::getline(list, line)) {
    ++line_number;
    if (line.empty() || line[0] == '#') continue;
    const std::string where = list_path + ":" + std::to_string(line_number);
    std::istringstream fields(line);
    std::string file;
    double p[7];
    if (!(fields >> file >> p[0] >> p[1] >> p[2] >> p[3] >> p[4] >> p[5] >> p[6])) {
      return Status::Error(where + ": expected 'depth_file tx ty tz qx qy qz qw'");
    }
    const double norm = std::sqrt(p[3] * p[3] + p[4] * p[4] + p[5] * p[5] + p[6] * p[6]);
    if (!(std::abs(norm - 1.0) < 1e-2)) {
      return Status::Error(where + ": quaternion is not unit length (norm " + std::to_string(norm) +
                           ")");
    }
    // The file name is the capture time: depth/1311877813.991479.png.
    std::string base = file.substr(file.find_last_of('/') + 1);
    base = base.substr(0, base.rfind(".png"));
    fusion::v1::RecordedTime stamp;
    if (Status s = ParseStamp(where + ": time stamp in file name", base, &stamp); !s.ok()) {
      return s;
    }

    std::uint32_t width = 0, height = 0;
    std::vector<std::uint16_t> depth;
    if (Status s = ReadPng16(options.directory + "/" + file, &width, &height, &depth); !s.ok()) {
      return s.WithContext(where);
    }
    fusion::v1::RecordedCloud cloud;
    auto* pose = cloud.mutable_t_world_sensor();
    pose->set_tx(p[0]);
    pose->set_ty(p[1]);
    pose->set_tz(p[2]);
    pose->set_qx(p[3] / norm);
    pose->set_qy(p[4] / norm);
    pose->set_qz(p[5] / norm);
    pose->set_qw(p[6] / norm);
    const std::uint32_t out_width = (width + options.stride - 1) / options.stride;
    const std::uint32_t out_height = (height + options.stride - 1) / options.stride;
    cloud.set_width(out_width);
    cloud.set_height(out_height);
    cloud.mutable_xyz_f32le()->reserve(static_cast<std::size_t>(out_width) * out_height * 12);
    for (std::uint32_t v = 0; v < height; v += options.stride) {
      for (std::uint32_t u = 0; u < width; u += options.stride) {
        const std::uint16_t raw = depth[static_cast<std::size_t>(v) * width + u];
        if (raw == 0) {  // missing measurement: no information, not free space
          AppendPoint(kNaN, kNaN, kNaN, &cloud);
          continue;
        }
        const double z_m = raw / options.depth_scale;
        AppendPoint(static_cast<float>((u - options.cx_px) * z_m / options.fx_px),
                    static_cast<float>((v - options.cy_px) * z_m / options.fy_px),
                    static_cast<float>(z_m), &cloud);
      }
    }
    ++frames;
    SetIdentity(options.sensor_id, frames, 0.0, file, &cloud);
    *cloud.mutable_stamp() = stamp;
    cloud.set_receive_time_unix_ns(static_cast<std::int64_t>(stamp.sec()) * 1000000000 +
                                   stamp.nanosec());
    if (Status s = sink(std::move(cloud)); !s.ok()) return s;
    if (options.max_frames != 0 && frames >= options.max_frames) break;
  }
  if (frames == 0) return Status::Error(list_path + ": no frames listed");
  return Status::Ok();
}

// ---------------------------------------------------------------------------------------------
// PCD

namespace {

struct PcdField {
  std::string name;
  std::size_t size_bytes = 4;
  char type = 'F';
  std::size_t count = 1;
  std::size_t offset_bytes = 0;  // within a point (binary)
  std::size_t first_value = 0;   // index of its first value among a point's values (ascii)
};

double ReadScalar(const unsigned char* p, const PcdField& f) {
  if (f.type == 'F' && f.size_bytes == 4) {
    float v;
    std::memcpy(&v, p, 4);
    return v;
  }
  double v;
  std::memcpy(&v, p, 8);
  return v;
}

}  // namespace

Status ReadPcd(const std::string& path, fusion::v1::RecordedCloud* cloud, bool apply_viewpoint) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return Status::Error("cannot open " + path + ": " + std::strerror(errno));
  std::string content((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const auto error = [&](const std::string& message) {
    return Status::Error(path + ": " + message);
  };

  std::vector<PcdField> fields;
  std::uint64_t width = 0, height = 1, points = 0;
  bool have_points = false;
  double viewpoint[7] = {0, 0, 0, 1, 0, 0, 0};  // tx ty tz qw qx qy qz
  std::string data_kind;
  std::size_t pos = 0, line_number = 0;
  while (data_kind.empty()) {
    if (pos >= content.size()) return error("header ends before the DATA line");
    std::size_t eol = content.find('\n', pos);
    if (eol == std::string::npos) eol = content.size();
    std::string line = content.substr(pos, eol - pos);
    pos = std::min(eol + 1, content.size());  // a last line without '\n' ends the file
    ++line_number;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (line.empty() || line[0] == '#') continue;
    std::istringstream words(line);
    std::string key;
    words >> key;
    std::vector<std::string> values;
    for (std::string w; words >> w;) values.push_back(w);
    const std::string where = "header line " + std::to_string(line_number) + " (" + key + ")";
    if (key == "VERSION") continue;
    if (key == "FIELDS" || key == "COLUMNS") {
      fields.assign(values.size(), PcdField{});
      for (std::size_t i = 0; i < values.size(); ++i) fields[i].name = values[i];
    } else if (key == "SIZE" || key == "TYPE" || key == "COUNT") {
      if (values.size() != fields.size())
        return error(where + ": " + std::to_string(values.size()) + " values for " +
                     std::to_string(fields.size()) + " fields");
      for (std::size_t i = 0; i < values.size(); ++i) {
        std::uint64_t n = 0;
        if (key == "TYPE") {
          if (values[i].size() != 1 || std::string("FIU").find(values[i][0]) == std::string::npos)
            return error(where + ": unknown type '" + values[i] + "'");
          fields[i].type = values[i][0];
        } else if (Status s = ParseUint(where, values[i], &n); !s.ok() || n == 0 || n > 1u << 20) {
          return error(where + ": bad value '" + values[i] + "'");
        } else {
          (key == "SIZE" ? fields[i].size_bytes : fields[i].count) = n;
        }
      }
    } else if (key == "WIDTH" || key == "HEIGHT" || key == "POINTS") {
      std::uint64_t n = 0;
      if (values.size() != 1) return error(where + ": expected one value");
      if (Status s = ParseUint(where, values[0], &n); !s.ok()) return error(s.message());
      if (key == "WIDTH") width = n;
      if (key == "HEIGHT") height = n;
      if (key == "POINTS") points = n, have_points = true;
    } else if (key == "VIEWPOINT") {
      if (values.size() != 7) return error(where + ": expected tx ty tz qw qx qy qz");
      for (int i = 0; i < 7; ++i) {
        if (Status s = ParseDouble(where, values[i], &viewpoint[i]); !s.ok())
          return error(s.message());
      }
    } else if (key == "DATA") {
      if (values.size() != 1) return error(where + ": expected ascii, binary or binary_compressed");
      data_kind = values[0];
    } else {
      return error(where + ": unknown header keyword");
    }
  }
  if (fields.empty()) return error("no FIELDS line");
  if (!have_points) points = width * height;
  if (width * height != points || points == 0) {
    return error("WIDTH x HEIGHT = " + std::to_string(width * height) +
                 " but POINTS = " + std::to_string(points));
  }
  if (points > (1ull << 28)) return error("implausible point count " + std::to_string(points));
  std::size_t point_step = 0, values_per_point = 0;
  int xyz_field[3] = {-1, -1, -1};
  // A point of at most 1 MiB (and so points x point size below 2^48: no overflow below).
  constexpr std::size_t kMaxPointBytes = std::size_t{1} << 20;
  for (std::size_t i = 0; i < fields.size(); ++i) {
    fields[i].offset_bytes = point_step;
    fields[i].first_value = values_per_point;
    if (fields[i].count > kMaxPointBytes / fields[i].size_bytes ||
        point_step + fields[i].size_bytes * fields[i].count > kMaxPointBytes) {
      return error("a point of more than 1 MiB (SIZE x COUNT summed over the fields)");
    }
    point_step += fields[i].size_bytes * fields[i].count;
    values_per_point += fields[i].count;
    for (int a = 0; a < 3; ++a) {
      if (fields[i].name == std::string(1, static_cast<char>('x' + a)))
        xyz_field[a] = static_cast<int>(i);
    }
  }
  for (int a = 0; a < 3; ++a) {
    if (xyz_field[a] < 0)
      return error(std::string("no field '") + static_cast<char>('x' + a) + "'");
    const PcdField& f = fields[static_cast<std::size_t>(xyz_field[a])];
    if (f.type != 'F' || (f.size_bytes != 4 && f.size_bytes != 8)) {
      return error("field " + f.name + " must be TYPE F with SIZE 4 or 8");
    }
  }

  // Sized only once the data is known to hold the points: the header alone may claim 2^28 of
  // them (3 GB of floats from a 100-byte file).
  std::vector<float> xyz;
  if (data_kind == "ascii") {
    std::istringstream body(content.substr(pos));
    std::string line;
    std::uint64_t i = 0;
    while (i < points && std::getline(body, line)) {
      ++line_number;
      std::istringstream words(line);
      std::vector<std::string> tokens;
      for (std::string w; words >> w;) tokens.push_back(w);
      if (tokens.empty()) continue;
      if (tokens.size() != values_per_point) {
        return error("line " + std::to_string(line_number) + ": expected " +
                     std::to_string(values_per_point) + " values, got " +
                     std::to_string(tokens.size()));
      }
      xyz.resize(3 * (i + 1));
      for (int a = 0; a < 3; ++a) {
        const std::string& t = tokens[fields[static_cast<std::size_t>(xyz_field[a])].first_value];
        char* end = nullptr;
        const double v = std::strtod(t.c_str(), &end);  // accepts "nan"
        if (end != t.c_str() + t.size())
          return error("line " + std::to_string(line_number) + ": '" + t + "' is not a number");
        xyz[3 * i + a] = static_cast<float>(v);
      }
      ++i;
    }
    if (i < points)
      return error("ascii data ends after " + std::to_string(i) + " of " + std::to_string(points) +
                   " points");
  } else if (data_kind == "binary") {
    if (content.size() - pos < points * point_step) {
      return error("binary data has " + std::to_string(content.size() - pos) + " bytes, needs " +
                   std::to_string(points * point_step));
    }
    xyz.assign(points * 3, kNaN);
    const auto* data = reinterpret_cast<const unsigned char*>(content.data() + pos);
    for (std::uint64_t i = 0; i < points; ++i) {
      for (int a = 0; a < 3; ++a) {
        const PcdField& f = fields[static_cast<std::size_t>(xyz_field[a])];
        xyz[3 * i + a] = static_cast<float>(ReadScalar(data + i * point_step + f.offset_bytes, f));
      }
    }
  } else if (data_kind == "binary_compressed") {
    if (content.size() - pos < 8) return error("binary_compressed data lacks its size header");
    std::uint32_t sizes[2];
    std::memcpy(sizes, content.data() + pos, 8);
    const std::uint32_t compressed = sizes[0], uncompressed = sizes[1];
    if (uncompressed != points * point_step) {
      return error("binary_compressed: uncompressed size " + std::to_string(uncompressed) +
                   " != points x point size " + std::to_string(points * point_step));
    }
    if (content.size() - pos - 8 < compressed) {
      return error("binary_compressed: truncated (" + std::to_string(compressed) +
                   " compressed bytes announced, " + std::to_string(content.size() - pos - 8) +
                   " present)");
    }
    // An LZF back-reference of 3 bytes yields at most 264: anything beyond 88x is corrupt (and
    // would otherwise be allocated before the data is looked at).
    if (uncompressed > std::uint64_t{88} * compressed) {
      return error("binary_compressed: " + std::to_string(compressed) +
                   " compressed bytes cannot hold " + std::to_string(uncompressed));
    }
    std::vector<unsigned char> data(uncompressed);
    if (LzfDecompress(content.data() + pos + 8, compressed, data.data(), data.size()) !=
        uncompressed) {
      return error("binary_compressed: corrupt LZF data");
    }
    xyz.assign(points * 3, kNaN);
    // Column-wise: all values of field 0, then of field 1, ...
    for (int a = 0; a < 3; ++a) {
      const PcdField& f = fields[static_cast<std::size_t>(xyz_field[a])];
      const unsigned char* column = data.data() + points * f.offset_bytes;
      for (std::uint64_t i = 0; i < points; ++i) {
        xyz[3 * i + a] = static_cast<float>(ReadScalar(column + i * f.size_bytes * f.count, f));
      }
    }
  } else {
    return error("DATA '" + data_kind + "' is not ascii, binary or binary_compressed");
  }

  cloud->Clear();
  auto* pose = cloud->mutable_t_world_sensor();
  double qnorm = std::sqrt(viewpoint[3] * viewpoint[3] + viewpoint[4] * viewpoint[4] +
                           viewpoint[5] * viewpoint[5] + viewpoint[6] * viewpoint[6]);
  if (qnorm < 1e-9) return error("VIEWPOINT quaternion is zero");
  // Components near 1e200 are finite, but their norm is not: the pose would become all zero.
  if (!std::isfinite(qnorm)) return error("VIEWPOINT quaternion is too large to normalize");
  if (!apply_viewpoint) {
    viewpoint[0] = viewpoint[1] = viewpoint[2] = viewpoint[4] = viewpoint[5] = viewpoint[6] = 0;
    viewpoint[3] = qnorm = 1;
  }
  pose->set_tx(viewpoint[0]);
  pose->set_ty(viewpoint[1]);
  pose->set_tz(viewpoint[2]);
  pose->set_qw(viewpoint[3] / qnorm);
  pose->set_qx(viewpoint[4] / qnorm);
  pose->set_qy(viewpoint[5] / qnorm);
  pose->set_qz(viewpoint[6] / qnorm);
  const bool identity =
      viewpoint[0] == 0 && viewpoint[1] == 0 && viewpoint[2] == 0 && pose->qw() == 1.0;
  if (!identity) {
    // PCD points share the cloud's frame; the viewpoint is the sensor's pose in it. Express
    // them in the sensor frame: p_sensor = R^T (p - t).
    for (std::uint64_t i = 0; i < points; ++i) {
      const double d[3] = {xyz[3 * i] - viewpoint[0], xyz[3 * i + 1] - viewpoint[1],
                           xyz[3 * i + 2] - viewpoint[2]};
      double r[3];
      Rotate(*pose, /*inverse=*/true, d, r);
      for (int a = 0; a < 3; ++a) xyz[3 * i + a] = static_cast<float>(r[a]);
    }
  }
  cloud->set_width(static_cast<std::uint32_t>(width));
  cloud->set_height(static_cast<std::uint32_t>(height));
  cloud->set_xyz_f32le(std::string(reinterpret_cast<const char*>(xyz.data()), xyz.size() * 4));
  return Status::Ok();
}

// ---------------------------------------------------------------------------------------------
// Text scans

namespace {

// Reads a whole file, through `bzip2 -dc` when it ends in .bz2.
Status ReadText(const std::string& path, std::string* text) {
  if (!EndsWith(path, ".bz2")) {
    std::ifstream in(path, std::ios::binary);
    if (!in) return Status::Error("cannot open " + path + ": " + std::strerror(errno));
    text->assign((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    return Status::Ok();
  }
  if (access(path.c_str(), R_OK) != 0)
    return Status::Error("cannot open " + path + ": " + std::strerror(errno));
  int pipe_fds[2];
  if (pipe(pipe_fds) != 0) return Status::Error(std::string("pipe: ") + std::strerror(errno));
  const pid_t child = fork();
  if (child < 0) return Status::Error(std::string("fork: ") + std::strerror(errno));
  if (child == 0) {
    dup2(pipe_fds[1], STDOUT_FILENO);
    close(pipe_fds[0]);
    close(pipe_fds[1]);
    execlp("bzip2", "bzip2", "-dc", "--", path.c_str(), static_cast<char*>(nullptr));
    _exit(127);
  }
  close(pipe_fds[1]);
  char buffer[1 << 16];
  for (;;) {
    const ssize_t n = read(pipe_fds[0], buffer, sizeof buffer);
    if (n > 0) text->append(buffer, static_cast<std::size_t>(n));
    if (n == 0 || (n < 0 && errno != EINTR)) break;
  }
  close(pipe_fds[0]);
  int status = 0;
  waitpid(child, &status, 0);
  if (!WIFEXITED(status) || WEXITSTATUS(status) != 0) {
    return Status::Error(path + ": bzip2 -dc failed" +
                         std::string(WIFEXITED(status) && WEXITSTATUS(status) == 127
                                         ? " (bzip2 not installed?)"
                                         : " (corrupt or truncated .bz2?)"));
  }
  return Status::Ok();
}

}  // namespace

Status ReadXyzScan(const std::string& path, const fusion::v1::RecordedPose& pose,
                   std::vector<fusion::v1::RecordedCloud>* clouds) {
  std::string text;
  if (Status s = ReadText(path, &text); !s.ok()) return s;
  clouds->clear();
  fusion::v1::RecordedCloud current;
  *current.mutable_t_world_sensor() = pose;
  bool have_current = false;
  const auto finish = [&]() {
    if (!have_current) return;
    current.set_width(static_cast<std::uint32_t>(current.xyz_f32le().size() / 12));
    current.set_height(1);
    clouds->push_back(std::move(current));
    current.Clear();
  };
  std::size_t pos = 0, line_number = 0;
  while (pos < text.size()) {
    std::size_t eol = text.find('\n', pos);
    if (eol == std::string::npos) eol = text.size();
    const char* p = text.c_str() + pos;
    const char* line_end = text.c_str() + eol;
    pos = eol + 1;
    ++line_number;
    while (p < line_end && (*p == ' ' || *p == '\t' || *p == '\r')) ++p;
    if (p == line_end || *p == '#') continue;
    const std::string where = path + ":" + std::to_string(line_number);
    if (line_end - p >= 4 && std::strncmp(p, "NODE", 4) == 0) {
      finish();
      std::istringstream words(std::string(p + 4, line_end));
      double x, y, z, roll, pitch, yaw;
      if (!(words >> x >> y >> z >> roll >> pitch >> yaw)) {
        return Status::Error(where + ": expected 'NODE x y z roll pitch yaw'");
      }
      const octomath::Pose6D node(x, y, z, roll, pitch, yaw);
      auto* node_pose = current.mutable_t_world_sensor();
      node_pose->set_tx(x);
      node_pose->set_ty(y);
      node_pose->set_tz(z);
      node_pose->set_qw(node.rot().u());
      node_pose->set_qx(node.rot().x());
      node_pose->set_qy(node.rot().y());
      node_pose->set_qz(node.rot().z());
      have_current = true;
      continue;
    }
    double v[3];
    char* end = nullptr;
    const char* q = p;
    for (int a = 0; a < 3; ++a) {
      v[a] = std::strtod(q, &end);
      if (end == q || !std::isfinite(v[a])) {
        return Status::Error(where + ": expected 'x y z' in metres, got '" +
                             std::string(p, line_end) + "'");
      }
      q = end;
    }
    while (q < line_end && (*q == ' ' || *q == '\t' || *q == '\r')) ++q;
    if (q != line_end) {
      return Status::Error(where + ": trailing text after 'x y z': '" + std::string(p, line_end) +
                           "'");
    }
    AppendPoint(static_cast<float>(v[0]), static_cast<float>(v[1]), static_cast<float>(v[2]),
                &current);
    have_current = true;
  }
  finish();
  if (clouds->empty()) return Status::Error(path + ": no points");
  return Status::Ok();
}

// ---------------------------------------------------------------------------------------------
// OctoMap scan graphs

namespace {

// octomap::ScanGraph::readBinary trusts its input (a garbage file asserts or allocates
// gigabytes), so walk the layout first. OctoMap 1.9 writes, little-endian:
//   uint32 nodes, nodes x {uint32 points, points x vec3, pose, uint32 id},
//   uint32 edges, edges x {uint32 first_id, uint32 second_id, pose, double weight}
// with vec3 = int32 3 + 3 doubles, quaternion = int32 4 + 4 doubles, pose = vec3 quaternion.
Status ValidateScanGraph(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return Status::Error("cannot open " + path + ": " + std::strerror(errno));
  const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  std::size_t pos = 0;
  const auto error = [&](const std::string& what) {
    return Status::Error(path + ": not an OctoMap binary scan graph: " + what + " at byte " +
                         std::to_string(pos));
  };
  const auto u32 = [&](std::uint32_t* v) {
    if (bytes.size() - pos < 4) return false;
    std::memcpy(v, bytes.data() + pos, 4);
    pos += 4;
    return true;
  };
  const auto vector_of = [&](std::uint32_t n) {  // marker n + n doubles
    std::uint32_t marker = 0;
    if (!u32(&marker) || marker != n || bytes.size() - pos < 8u * n) return false;
    pos += 8u * n;
    return true;
  };
  std::uint32_t nodes = 0, edges = 0;
  if (!u32(&nodes)) return error("no node count");
  if (nodes == 0 || nodes > bytes.size() / 72)
    return error("implausible node count " + std::to_string(nodes));
  std::vector<std::uint32_t> ids;
  for (std::uint32_t n = 0; n < nodes; ++n) {
    std::uint32_t points = 0, id = 0;
    if (!u32(&points)) return error("node " + std::to_string(n) + ": no point count");
    if (points > (bytes.size() - pos) / 28)
      return error("node " + std::to_string(n) + ": point count " + std::to_string(points) +
                   " exceeds the file");
    for (std::uint32_t i = 0; i < points; ++i) {
      if (!vector_of(3))
        return error("node " + std::to_string(n) + " point " + std::to_string(i) + ": bad vector");
    }
    if (!vector_of(3) || !vector_of(4)) return error("node " + std::to_string(n) + ": bad pose");
    if (!u32(&id)) return error("node " + std::to_string(n) + ": no id");
    ids.push_back(id);
  }
  if (!u32(&edges)) return error("no edge count");
  if (edges > (bytes.size() - pos) / 80)
    return error("edge count " + std::to_string(edges) + " exceeds the file");
  for (std::uint32_t e = 0; e < edges; ++e) {
    std::uint32_t first = 0, second = 0;
    if (!u32(&first) || !u32(&second)) return error("edge " + std::to_string(e) + ": no node ids");
    if (std::find(ids.begin(), ids.end(), first) == ids.end() ||
        std::find(ids.begin(), ids.end(), second) == ids.end()) {
      return error("edge " + std::to_string(e) + ": unknown node id");
    }
    if (!vector_of(3) || !vector_of(4) || bytes.size() - pos < 8)
      return error("edge " + std::to_string(e) + ": bad constraint");
    pos += 8;
  }
  if (pos != bytes.size()) return error(std::to_string(bytes.size() - pos) + " trailing bytes");
  return Status::Ok();
}

}  // namespace

Status ReadScanGraph(const std::string& path, std::vector<fusion::v1::RecordedCloud>* clouds) {
  if (Status s = ValidateScanGraph(path); !s.ok()) return s;
  octomap::ScanGraph graph;
  if (!graph.readBinary(path)) return Status::Error(path + ": not a readable OctoMap scan graph");
  if (graph.size() == 0) return Status::Error(path + ": the scan graph has no nodes");
  clouds->clear();
  for (const octomap::ScanNode* node : graph) {
    fusion::v1::RecordedCloud cloud;
    auto* pose = cloud.mutable_t_world_sensor();
    pose->set_tx(node->pose.x());
    pose->set_ty(node->pose.y());
    pose->set_tz(node->pose.z());
    pose->set_qw(node->pose.rot().u());
    pose->set_qx(node->pose.rot().x());
    pose->set_qy(node->pose.rot().y());
    pose->set_qz(node->pose.rot().z());
    const octomap::Pointcloud* scan = node->scan;
    const std::size_t n = scan != nullptr ? scan->size() : 0;
    cloud.mutable_xyz_f32le()->reserve(n * 12);
    for (std::size_t i = 0; i < n; ++i) {
      const octomap::point3d& p = (*scan)[i];
      AppendPoint(p.x(), p.y(), p.z(), &cloud);
    }
    cloud.set_width(static_cast<std::uint32_t>(n));
    cloud.set_height(1);
    clouds->push_back(std::move(cloud));
  }
  return Status::Ok();
}

}  // namespace fusion::clients
