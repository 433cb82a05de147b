// PCD reader: the header (pcd_header.cc), then the points in one of the three encodings, then
// the VIEWPOINT as the sensor pose with the points re-expressed in the sensor frame.
#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <fstream>
#include <iterator>
#include <limits>
#include <sstream>

#include "fusion/clients/importers.h"
#include "fusion/clients/lzf.h"
#include "pcd_header.h"

namespace fusion::clients {
namespace {

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

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

// The decoders below fill xyz (3 floats a point, in the file's frame) only once the data is
// known to hold the points: the header alone may claim 2^28 of them (3 GB of floats from a
// 100-byte file).

// DATA ascii: one point a line, its values separated by blanks; blank lines are skipped.
Status DecodeAscii(const std::string& content, const PcdHeader& header, const PcdLayout& layout,
                   std::vector<float>* xyz) {
  std::istringstream body(content.substr(header.data_offset_bytes));
  std::string line;
  std::size_t line_number = header.line_count;
  std::uint64_t i = 0;
  while (i < header.points && std::getline(body, line)) {
    ++line_number;
    std::istringstream words(line);
    std::vector<std::string> tokens;
    for (std::string w; words >> w;) tokens.push_back(w);
    if (tokens.empty()) continue;
    if (tokens.size() != layout.values_per_point) {
      return Status::Error("line " + std::to_string(line_number) + ": expected " +
                           std::to_string(layout.values_per_point) + " values, got " +
                           std::to_string(tokens.size()));
    }
    xyz->resize(3 * (i + 1));
    for (int a = 0; a < 3; ++a) {
      const std::string& t = tokens[header.fields[layout.xyz_field[a]].first_value];
      char* end = nullptr;
      const double v = std::strtod(t.c_str(), &end);  // accepts "nan"
      if (end != t.c_str() + t.size())
        return Status::Error("line " + std::to_string(line_number) + ": '" + t +
                             "' is not a number");
      (*xyz)[3 * i + a] = static_cast<float>(v);
    }
    ++i;
  }
  if (i < header.points)
    return Status::Error("ascii data ends after " + std::to_string(i) + " of " +
                         std::to_string(header.points) + " points");
  return Status::Ok();
}

// DATA binary: the points one after the other, each point_step bytes, fields in order.
Status DecodeBinary(const std::string& content, const PcdHeader& header, const PcdLayout& layout,
                    std::vector<float>* xyz) {
  const std::size_t pos = header.data_offset_bytes, points = header.points;
  const std::size_t point_step = layout.point_step_bytes;
  if (content.size() - pos < points * point_step) {
    return Status::Error("binary data has " + std::to_string(content.size() - pos) +
                         " bytes, needs " + std::to_string(points * point_step));
  }
  xyz->assign(points * 3, kNaN);
  const auto* data = reinterpret_cast<const unsigned char*>(content.data() + pos);
  for (std::uint64_t i = 0; i < points; ++i) {
    for (int a = 0; a < 3; ++a) {
      const PcdField& f = header.fields[layout.xyz_field[a]];
      (*xyz)[3 * i + a] = static_cast<float>(ReadScalar(data + i * point_step + f.offset_bytes, f));
    }
  }
  return Status::Ok();
}

// DATA binary_compressed: uint32 compressed size, uint32 uncompressed size, then LZF data
// that decompresses column-wise: all values of field 0, then of field 1, ...
Status DecodeBinaryCompressed(const std::string& content, const PcdHeader& header,
                              const PcdLayout& layout, std::vector<float>* xyz) {
  const std::size_t pos = header.data_offset_bytes, points = header.points;
  if (content.size() - pos < 8)
    return Status::Error("binary_compressed data lacks its size header");
  std::uint32_t sizes[2];
  std::memcpy(sizes, content.data() + pos, 8);
  const std::uint32_t compressed = sizes[0], uncompressed = sizes[1];
  if (uncompressed != points * layout.point_step_bytes) {
    return Status::Error("binary_compressed: uncompressed size " + std::to_string(uncompressed) +
                         " != points x point size " +
                         std::to_string(points * layout.point_step_bytes));
  }
  if (content.size() - pos - 8 < compressed) {
    return Status::Error("binary_compressed: truncated (" + std::to_string(compressed) +
                         " compressed bytes announced, " +
                         std::to_string(content.size() - pos - 8) + " present)");
  }
  // An LZF back-reference of 3 bytes yields at most 264: anything beyond 88x is corrupt (and
  // would otherwise be allocated before the data is looked at).
  if (uncompressed > std::uint64_t{88} * compressed) {
    return Status::Error("binary_compressed: " + std::to_string(compressed) +
                         " compressed bytes cannot hold " + std::to_string(uncompressed));
  }
  std::vector<unsigned char> data(uncompressed);
  if (LzfDecompress(content.data() + pos + 8, compressed, data.data(), data.size()) !=
      uncompressed) {
    return Status::Error("binary_compressed: corrupt LZF data");
  }
  xyz->assign(points * 3, kNaN);
  for (int a = 0; a < 3; ++a) {
    const PcdField& f = header.fields[layout.xyz_field[a]];
    const unsigned char* column = data.data() + points * f.offset_bytes;
    for (std::uint64_t i = 0; i < points; ++i) {
      (*xyz)[3 * i + a] = static_cast<float>(ReadScalar(column + i * f.size_bytes * f.count, f));
    }
  }
  return Status::Ok();
}

Status DecodePoints(const std::string& content, const PcdHeader& header, const PcdLayout& layout,
                    std::vector<float>* xyz) {
  if (header.data_kind == "ascii") return DecodeAscii(content, header, layout, xyz);
  if (header.data_kind == "binary") return DecodeBinary(content, header, layout, xyz);
  if (header.data_kind == "binary_compressed") {
    return DecodeBinaryCompressed(content, header, layout, xyz);
  }
  return Status::Error("DATA '" + header.data_kind + "' is not ascii, binary or binary_compressed");
}

// Last step: the pose from VIEWPOINT (the identity when it is not applied), the points
// (xyz, in the file's frame) re-expressed in the sensor frame.
Status FillCloud(const PcdHeader& header, bool apply_viewpoint, std::vector<float>* xyz,
                 fusion::v1::RecordedCloud* cloud) {
  cloud->Clear();
  double viewpoint[7];
  std::copy(std::begin(header.viewpoint), std::end(header.viewpoint), viewpoint);
  auto* pose = cloud->mutable_t_world_sensor();
  double qnorm = std::sqrt(viewpoint[3] * viewpoint[3] + viewpoint[4] * viewpoint[4] +
                           viewpoint[5] * viewpoint[5] + viewpoint[6] * viewpoint[6]);
  if (qnorm < 1e-9) return Status::Error("VIEWPOINT quaternion is zero");
  // Components near 1e200 are finite, but their norm is not: the pose would become all zero.
  if (!std::isfinite(qnorm)) return Status::Error("VIEWPOINT quaternion is too large to normalize");
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
    for (std::uint64_t i = 0; i < header.points; ++i) {
      const double d[3] = {(*xyz)[3 * i] - viewpoint[0], (*xyz)[3 * i + 1] - viewpoint[1],
                           (*xyz)[3 * i + 2] - viewpoint[2]};
      double r[3];
      Rotate(*pose, /*inverse=*/true, d, r);
      for (int a = 0; a < 3; ++a) (*xyz)[3 * i + a] = static_cast<float>(r[a]);
    }
  }
  cloud->set_width(static_cast<std::uint32_t>(header.width));
  cloud->set_height(static_cast<std::uint32_t>(header.height));
  cloud->set_xyz_f32le(std::string(reinterpret_cast<const char*>(xyz->data()), xyz->size() * 4));
  return Status::Ok();
}

}  // namespace

Status ReadPcd(const std::string& path, fusion::v1::RecordedCloud* cloud, bool apply_viewpoint) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return Status::Error("cannot open " + path + ": " + std::strerror(errno));
  const std::string content((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  PcdHeader header;
  PcdLayout layout;
  std::vector<float> xyz;
  Status s = ParsePcdHeader(content, &header);
  if (s.ok()) s = LayOutPcdFields(&header, &layout);
  if (s.ok()) s = DecodePoints(content, header, layout, &xyz);
  if (s.ok()) s = FillCloud(header, apply_viewpoint, &xyz, cloud);
  return s.WithContext(path);
}

}  // namespace fusion::clients
