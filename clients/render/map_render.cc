#include "map_render.h"

#include <png.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>

namespace fusion::render {
namespace {

constexpr double kPi = 3.14159265358979323846;

struct Voxel {
  Eigen::Vector3d centre;
  double size;
  double probability;
};

// Perceptually ordered blue -> cyan -> green -> yellow -> red ramp over t in [0, 1].
Eigen::Vector3d Ramp(double t) {
  t = std::clamp(t, 0.0, 1.0);
  static const Eigen::Vector3d kStops[] = {{0.19, 0.25, 0.80},
                                           {0.10, 0.70, 0.85},
                                           {0.20, 0.75, 0.30},
                                           {0.95, 0.85, 0.20},
                                           {0.85, 0.20, 0.15}};
  const double x = t * 4.0;
  const int i = std::min(3, static_cast<int>(x));
  return kStops[i] + (kStops[i + 1] - kStops[i]) * (x - i);
}

// The occupied leaves (occupancy at or above min_probability) and the box around their centres.
std::vector<Voxel> CollectOccupied(const octomap::OcTree& tree, const RenderOptions& options,
                                   Eigen::AlignedBox3d* box) {
  std::vector<Voxel> voxels;
  for (auto it = tree.begin_leafs(), end = tree.end_leafs(); it != end; ++it) {
    const double p = it->getOccupancy();
    if (p < options.min_probability) continue;
    const octomap::point3d c = it.getCoordinate();
    voxels.push_back({Eigen::Vector3d(c.x(), c.y(), c.z()), it.getSize(), p});
    box->extend(voxels.back().centre);
  }
  return voxels;
}

// A pinhole camera in the world frame: eye position, unit axes, focal length and principal
// point in pixels; distance and radius (metres) bound the depth of what it looks at.
struct Camera {
  Eigen::Vector3d eye, forward, right, down;
  double distance = 0, radius = 0;
  double focal_px = 0;
  Eigen::Vector2d centre_px;
};

// Looks at the box centre from the chosen direction, far enough to see all of it.
Camera PlaceCamera(const Eigen::AlignedBox3d& box, const RenderOptions& options) {
  Camera camera;
  const double az = options.view_azimuth_deg * kPi / 180.0;
  const double el = options.view_elevation_deg * kPi / 180.0;
  const Eigen::Vector3d towards_eye(std::cos(el) * std::cos(az), std::cos(el) * std::sin(az),
                                    std::sin(el));
  camera.radius = std::max(0.5 * box.diagonal().norm(), 0.05);
  const double half_fov = 0.5 * options.fov_deg * kPi / 180.0;
  camera.distance = camera.radius / std::sin(half_fov) * 1.05;
  camera.eye = box.center() + towards_eye * camera.distance;
  camera.forward = -towards_eye;
  camera.right = camera.forward.cross(Eigen::Vector3d::UnitZ());
  if (camera.right.norm() < 1e-6) camera.right = Eigen::Vector3d::UnitX();
  camera.right.normalize();
  camera.down = camera.forward.cross(camera.right);
  camera.focal_px = 0.5 * options.height_px / std::tan(half_fov);
  camera.centre_px = Eigen::Vector2d(0.5 * options.width_px, 0.5 * options.height_px);
  return camera;
}

// Zoom and centre on what is drawn: the voxels' extent in normalised image coordinates
// (x / z, y / z) fills 90 % of the picture's width or height, whichever binds first.
void ZoomToVoxels(const std::vector<Voxel>& voxels, const Image& image, Camera* camera) {
  Eigen::AlignedBox2d extent;
  for (const Voxel& v : voxels) {
    const Eigen::Vector3d rel = v.centre - camera->eye;
    const double z = rel.dot(camera->forward);
    if (z <= 1e-3) continue;
    const double half_size = 0.5 * v.size / z;
    const Eigen::Vector2d uv(rel.dot(camera->right) / z, rel.dot(camera->down) / z);
    extent.extend(uv - Eigen::Vector2d::Constant(half_size));
    extent.extend(uv + Eigen::Vector2d::Constant(half_size));
  }
  if (!extent.isEmpty()) {
    const Eigen::Vector2d size = extent.sizes().cwiseMax(1e-9);
    camera->focal_px = 0.9 * std::min(image.width / size.x(), image.height / size.y());
    camera->centre_px -= camera->focal_px * extent.center();
  }
}

// Draws one voxel as a square of `colour` (0..255 a channel) around pixel (u, w), z-buffered in
// depth (metres along the view); true if any pixel of it is visible.
bool DrawSquare(double u, double w, int half, double z, const Eigen::Vector3d& colour,
                std::vector<float>* depth, Image* image) {
  bool drawn = false;
  for (int y = static_cast<int>(w) - half; y <= static_cast<int>(w) + half; ++y) {
    if (y < 0 || y >= image->height) continue;
    for (int x = static_cast<int>(u) - half; x <= static_cast<int>(u) + half; ++x) {
      if (x < 0 || x >= image->width) continue;
      const std::size_t i = static_cast<std::size_t>(y) * image->width + x;
      if (z >= (*depth)[i]) continue;
      (*depth)[i] = static_cast<float>(z);
      // Darken the square's border so neighbouring voxels stay distinguishable.
      const bool edge =
          std::abs(y - static_cast<int>(w)) == half || std::abs(x - static_cast<int>(u)) == half;
      const double k = edge ? 0.75 : 1.0;
      image->rgb[3 * i] = static_cast<std::uint8_t>(colour.x() * k);
      image->rgb[3 * i + 1] = static_cast<std::uint8_t>(colour.y() * k);
      image->rgb[3 * i + 2] = static_cast<std::uint8_t>(colour.z() * k);
      drawn = true;
    }
  }
  return drawn;
}

}  // namespace

Image RenderOccupied(const octomap::OcTree& tree, const RenderOptions& options) {
  Image image;
  image.width = options.width_px;
  image.height = options.height_px;
  image.rgb.assign(static_cast<std::size_t>(image.width) * image.height * 3, 0);
  for (std::size_t i = 0; i < image.rgb.size(); i += 3) {  // light grey background
    image.rgb[i] = 235;
    image.rgb[i + 1] = 235;
    image.rgb[i + 2] = 240;
  }

  Eigen::AlignedBox3d box;
  const std::vector<Voxel> voxels = CollectOccupied(tree, options, &box);
  if (voxels.empty()) return image;
  Camera camera = PlaceCamera(box, options);
  ZoomToVoxels(voxels, image, &camera);

  std::vector<float> depth(static_cast<std::size_t>(image.width) * image.height,
                           std::numeric_limits<float>::infinity());
  const double z_min = box.min().z();
  const double z_span = std::max(box.max().z() - z_min, 1e-6);
  const double near = camera.distance - camera.radius;
  const double far = camera.distance + camera.radius;
  for (const Voxel& v : voxels) {
    const Eigen::Vector3d rel = v.centre - camera.eye;
    const double z = rel.dot(camera.forward);
    if (z <= 1e-3) continue;
    const double u = camera.centre_px.x() + camera.focal_px * rel.dot(camera.right) / z;
    const double w = camera.centre_px.y() + camera.focal_px * rel.dot(camera.down) / z;
    const int half = std::max(1, static_cast<int>(std::ceil(0.6 * camera.focal_px * v.size / z)));
    const double t =
        options.color_by == ColorBy::kHeight
            ? (v.centre.z() - z_min) / z_span
            : (v.probability - options.min_probability) / (1.0 - options.min_probability);
    // Nearer voxels brighter: depth cue without lighting.
    const double shade = 1.0 - 0.45 * std::clamp((z - near) / (far - near), 0.0, 1.0);
    const Eigen::Vector3d colour = Ramp(t) * shade * 255.0;
    const bool drawn = DrawSquare(u, w, half, z, colour, &depth, &image);
    image.voxels_drawn += drawn ? 1 : 0;
  }
  return image;
}

bool WritePng(const std::string& path, const Image& image, std::string* error) {
  if (image.width <= 0 || image.height <= 0 ||
      image.rgb.size() != static_cast<std::size_t>(image.width) * image.height * 3) {
    *error = "image has no pixels or a wrong buffer size";
    return false;
  }
  FILE* file = std::fopen(path.c_str(), "wb");
  if (!file) {
    *error = "cannot open '" + path + "' for writing";
    return false;
  }
  png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, nullptr, nullptr, nullptr);
  png_infop info = png ? png_create_info_struct(png) : nullptr;
  if (!png || !info || setjmp(png_jmpbuf(png))) {
    png_destroy_write_struct(&png, &info);
    std::fclose(file);
    *error = "libpng failed writing '" + path + "'";
    return false;
  }
  png_init_io(png, file);
  png_set_IHDR(png, info, image.width, image.height, 8, PNG_COLOR_TYPE_RGB, PNG_INTERLACE_NONE,
               PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
  png_write_info(png, info);
  for (int y = 0; y < image.height; ++y) {
    png_write_row(png, image.rgb.data() + static_cast<std::size_t>(y) * image.width * 3);
  }
  png_write_end(png, nullptr);
  png_destroy_write_struct(&png, &info);
  if (std::fclose(file) != 0) {
    *error = "cannot finish writing '" + path + "'";
    return false;
  }
  return true;
}

}  // namespace fusion::render
