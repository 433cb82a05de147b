// The map picture: occupied voxels land where the camera model puts them, free and unknown
// ones are not drawn, and the PNG written reads back with the same pixels.
#include <png.h>

#include <cmath>
#include <cstdio>
#include <string>

#include <gtest/gtest.h>

#include "map_render.h"

namespace fusion::render {
namespace {

octomap::OcTree Wall(double resolution_m) {
  octomap::OcTree tree(resolution_m);
  // A 1 m x 1 m wall in the plane x = 2, occupied; free voxels in front of it.
  const int n = static_cast<int>(std::lround(1.0 / resolution_m));
  for (int i = 0; i < n; ++i) {
    for (int j = 0; j < n; ++j) {
      const float y = static_cast<float>(-0.5 + (i + 0.5) * resolution_m);
      const float z = static_cast<float>((j + 0.5) * resolution_m);
      tree.updateNode(octomap::point3d(2.0f, y, z), true);
      tree.updateNode(octomap::point3d(1.0f, y, z), false);
    }
  }
  return tree;
}

int CountNonBackground(const Image& image) {
  int count = 0;
  for (std::size_t i = 0; i < image.rgb.size(); i += 3) {
    count += !(image.rgb[i] == 235 && image.rgb[i + 1] == 235 && image.rgb[i + 2] == 240);
  }
  return count;
}

TEST(MapRenderTest, DrawsOnlyOccupiedVoxelsAndFramesThem) {
  const auto tree = Wall(0.05);
  RenderOptions options;
  options.width_px = 200;
  options.height_px = 150;
  options.view_azimuth_deg = 180.0;  // look along +x at the wall, from x < 2
  options.view_elevation_deg = 0.0;
  const Image image = RenderOccupied(tree, options);
  std::size_t occupied_leaves = 0;
  for (auto it = tree.begin_leafs(); it != tree.end_leafs(); ++it) {
    occupied_leaves += it->getOccupancy() > 0.5;
  }
  ASSERT_GT(occupied_leaves, 0u);
  EXPECT_EQ(image.voxels_drawn, occupied_leaves);
  // Seen face-on and framed, the wall covers a good part of the picture but not all of it.
  const int covered = CountNonBackground(image);
  EXPECT_GT(covered, 200 * 150 / 5);
  EXPECT_LT(covered, 200 * 150);
  // The centre pixel is on the wall; the corners are background.
  const std::size_t centre = (75 * 200 + 100) * 3;
  EXPECT_FALSE(image.rgb[centre] == 235 && image.rgb[centre + 2] == 240);
  EXPECT_EQ(image.rgb[0], 235);

  // Colour by height: the top row of the wall is red-ish, the bottom blue-ish.
  int top_y = -1, bottom_y = -1;
  for (int y = 0; y < 150; ++y) {
    const std::size_t i = (y * 200 + 100) * 3;
    if (!(image.rgb[i] == 235 && image.rgb[i + 2] == 240)) {
      if (top_y < 0) top_y = y;
      bottom_y = y;
    }
  }
  ASSERT_GE(top_y, 0);
  const std::size_t top = ((top_y + 2) * 200 + 100) * 3;
  const std::size_t bottom = ((bottom_y - 2) * 200 + 100) * 3;
  EXPECT_GT(image.rgb[top], image.rgb[top + 2]);           // red > blue at the top
  EXPECT_GT(image.rgb[bottom + 2], image.rgb[bottom]);     // blue > red at the bottom
}

TEST(MapRenderTest, EmptyMapGivesABackgroundPicture) {
  octomap::OcTree tree(0.1);
  tree.updateNode(octomap::point3d(1, 1, 1), false);
  const Image image = RenderOccupied(tree, RenderOptions{});
  EXPECT_EQ(image.voxels_drawn, 0u);
  EXPECT_EQ(CountNonBackground(image), 0);
}

TEST(MapRenderTest, PngRoundTrip) {
  RenderOptions options;
  options.width_px = 64;
  options.height_px = 48;
  const Image image = RenderOccupied(Wall(0.1), options);
  const std::string path = ::testing::TempDir() + "map_render_test.png";
  std::string error;
  ASSERT_TRUE(WritePng(path, image, &error)) << error;

  png_image read{};
  read.version = PNG_IMAGE_VERSION;
  ASSERT_TRUE(png_image_begin_read_from_file(&read, path.c_str()));
  read.format = PNG_FORMAT_RGB;
  std::vector<std::uint8_t> pixels(PNG_IMAGE_SIZE(read));
  ASSERT_TRUE(png_image_finish_read(&read, nullptr, pixels.data(), 0, nullptr));
  EXPECT_EQ(read.width, 64u);
  EXPECT_EQ(read.height, 48u);
  EXPECT_EQ(pixels, image.rgb);

  EXPECT_FALSE(WritePng("/nonexistent-dir/x.png", image, &error));
  EXPECT_NE(error.find("cannot open"), std::string::npos);
}

}  // namespace
}  // namespace fusion::render
