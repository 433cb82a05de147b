// Pictures of an occupancy map: occupied voxels projected through a virtual camera,
// z-buffered, shaded by depth and coloured by height or by probability (as in the paper's
// Fig. 5), written as PNG.
#pragma once

#include <octomap/OcTree.h>

#include <cstdint>
#include <string>
#include <vector>

namespace fusion::render {

enum class ColorBy { kHeight, kProbability };

struct RenderOptions {
  int width_px = 960;
  int height_px = 720;
  // Viewing direction: the camera looks at the centre of the occupied voxels from this
  // azimuth (about world z, from +x towards +y) and elevation (above the xy plane).
  double view_azimuth_deg = -135.0;
  double view_elevation_deg = 30.0;
  // Perspective of the camera; the picture is then zoomed so the drawn voxels fill 90 % of it.
  double fov_deg = 50.0;
  // Voxels drawn: occupancy at or above this (fusiond's default map.occupied_threshold, so the
  // picture shows what its queries call occupied).
  double min_probability = 0.55;
  ColorBy color_by = ColorBy::kHeight;
};

struct Image {
  int width = 0;
  int height = 0;
  std::vector<std::uint8_t> rgb;  // row-major, 3 bytes a pixel
  std::size_t voxels_drawn = 0;
};

// Renders the occupied leaves of `tree` (world frame, z up).
[[nodiscard]] Image RenderOccupied(const octomap::OcTree& tree, const RenderOptions& options);

// Writes an 8-bit RGB PNG; false with *error on failure.
bool WritePng(const std::string& path, const Image& image, std::string* error);

}  // namespace fusion::render
