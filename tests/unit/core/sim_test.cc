#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <fstream>

#include "fusion/core/local_grid.h"
#include "fusion/sim/experiment.h"
#include "fusion/sim/ground_truth.h"
#include "fusion/sim/scene.h"
#include "fusion/sim/simulator.h"

namespace fusion::sim {
namespace {

TEST(Scene, RaycastRectanglesAndBoxes) {
  const Scene scene = PaperBoardScene();
  const auto hit = scene.Raycast(Eigen::Vector3d::Zero(), Eigen::Vector3d::UnitX(), 10.0);
  ASSERT_TRUE(hit.has_value());
  EXPECT_NEAR(hit->range_m, PaperSetup::kBoardDistanceM, 1e-12);
  EXPECT_TRUE(hit->textured);
  const auto floor =
      scene.Raycast(Eigen::Vector3d::Zero(), Eigen::Vector3d(1, 0, -1).normalized(), 10.0);
  ASSERT_TRUE(floor.has_value());
  EXPECT_NEAR(floor->range_m, 0.41 * std::sqrt(2.0), 1e-9);
  EXPECT_FALSE(floor->textured);
  EXPECT_FALSE(scene.Raycast(Eigen::Vector3d::Zero(), Eigen::Vector3d::UnitZ(), 10.0).has_value());
  EXPECT_FALSE(scene.Raycast(Eigen::Vector3d::Zero(), Eigen::Vector3d::UnitX(), 1.0).has_value());

  Scene boxes;
  Box box;
  box.T_world_box.translation() = Eigen::Vector3d(3, 0, 0);
  box.T_world_box.linear() = Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitZ()).matrix();
  box.half_extents_m = Eigen::Vector3d(0.5, 0.5, 0.5);
  boxes.AddBox(box);
  const auto box_hit = boxes.Raycast(Eigen::Vector3d::Zero(), Eigen::Vector3d::UnitX(), 10.0);
  ASSERT_TRUE(box_hit.has_value());
  EXPECT_NEAR(box_hit->range_m, 3.0 - 0.5 / std::cos(0.3), 1e-9);
  EXPECT_NEAR(boxes.DistanceToSurface(Eigen::Vector3d(3, 0, 0)), 0.5, 1e-12);
  EXPECT_TRUE(boxes.SurfaceIntersects(
      Eigen::AlignedBox3d(Eigen::Vector3d(2.4, -0.01, -0.01), Eigen::Vector3d(2.6, 0.01, 0.01))));
  EXPECT_FALSE(boxes.SurfaceIntersects(  // inside the solid
      Eigen::AlignedBox3d(Eigen::Vector3d(2.9, -0.1, -0.1), Eigen::Vector3d(3.1, 0.1, 0.1))));
}

TEST(Scene, SurfaceTests) {
  const Scene scene = PaperBoardScene();
  EXPECT_NEAR(scene.DistanceToSurface(Eigen::Vector3d(1.70, 0.0, 0.2)), 0.05, 1e-12);
  EXPECT_NEAR(scene.DistanceToSurface(Eigen::Vector3d(1.0, 0.0, -0.30)), 0.11, 1e-12);
  EXPECT_TRUE(scene.SurfaceIntersects(
      Eigen::AlignedBox3d(Eigen::Vector3d(1.74, 0.0, 0.0), Eigen::Vector3d(1.76, 0.02, 0.02))));
  EXPECT_FALSE(scene.SurfaceIntersects(
      Eigen::AlignedBox3d(Eigen::Vector3d(1.70, 0.0, 0.0), Eigen::Vector3d(1.72, 0.02, 0.02))));
  // Beside the board.
  EXPECT_FALSE(scene.SurfaceIntersects(
      Eigen::AlignedBox3d(Eigen::Vector3d(1.74, 0.62, 0.0), Eigen::Vector3d(1.76, 0.64, 0.02))));
}

// A voxel that the board's rim only touches (its side at y = 0.6, its bottom at z = -0.3, on
// 2 cm voxel faces) holds none of its area; a solid's face lying in a voxel face belongs to the
// voxel inside the solid.
TEST(Scene, SurfaceTouchingAVoxelsFaceAlongItsRimHoldsNoneOfIt) {
  const Scene scene = PaperBoardScene();
  const auto voxel = [](double x, double y, double z) {
    return Eigen::AlignedBox3d(Eigen::Vector3d(x, y, z), Eigen::Vector3d(x, y, z).array() + 0.02);
  };
  EXPECT_TRUE(scene.SurfaceIntersects(voxel(1.74, 0.58, 0.0)));    // inside the rim
  EXPECT_FALSE(scene.SurfaceIntersects(voxel(1.74, 0.60, 0.0)));   // beside the side
  EXPECT_FALSE(scene.SurfaceIntersects(voxel(1.74, -0.62, 0.0)));  // the other side
  EXPECT_TRUE(scene.SurfaceIntersects(voxel(1.74, 0.0, -0.30)));   // the bottom row
  EXPECT_FALSE(scene.SurfaceIntersects(voxel(1.74, 0.0, -0.32)));  // under the bottom
  // A unit cube from x = 3 to 4: its face x = 3 belongs to the voxel inside it.
  Scene boxes;
  Box box;
  box.T_world_box.translation() = Eigen::Vector3d(3.5, 0.5, 0.5);
  box.half_extents_m = Eigen::Vector3d(0.5, 0.5, 0.5);
  boxes.AddBox(box);
  EXPECT_TRUE(boxes.SurfaceIntersects(voxel(3.0, 0.4, 0.4)));
  EXPECT_FALSE(boxes.SurfaceIntersects(voxel(2.98, 0.4, 0.4)));
  EXPECT_FALSE(boxes.SurfaceIntersects(voxel(3.4, 0.4, 0.4)));  // inside the solid
}

TEST(SceneFile, ParsesAndRejects) {
  std::string error;
  const auto scene = ParseScene(
      "# a wall and a crate\n"
      "rect wall 3 0 1  0 1 0  0 0 1  4 2\n"
      "rect floor 2 0 0  1 0 0  0 1 0  4 4 untextured  # trailing comment\n"
      "box crate 1.5 0.5 0.25  0.5 0.5 0.5  0 0 45\n",
      &error);
  ASSERT_TRUE(scene.has_value()) << error;
  EXPECT_EQ(scene->rectangles().size(), 2u);
  EXPECT_EQ(scene->boxes().size(), 1u);
  EXPECT_FALSE(scene->rectangles()[1].textured);
  EXPECT_FALSE(ParseScene("sphere s 0 0 0 1\n", &error).has_value());
  EXPECT_NE(error.find("line 1"), std::string::npos);
  EXPECT_FALSE(ParseScene("\nrect r 0 0 0 1 0 0 1 0 0 1 1\n", &error).has_value());  // parallel
  EXPECT_NE(error.find("line 2"), std::string::npos);
  EXPECT_FALSE(ParseScene("rect r 0 0 x 1 0 0 0 1 0 1 1\n", &error).has_value());
  EXPECT_FALSE(ParseScene("box b 0 0 0 1 1\n", &error).has_value());
  EXPECT_FALSE(ParseScene("box b 0 0 0 1 -1 1\n", &error).has_value());
  EXPECT_FALSE(ParseScene("rect r 0 0 nan 1 0 0 0 1 0 1 1\n", &error).has_value());
  EXPECT_FALSE(LoadSceneFile("/nonexistent/scene.txt", &error).has_value());
  const std::string path = std::string(FUSION_BINARY_DIR) + "/sim_test_scene.txt";
  {
    std::ofstream file(path);
    file << "rect board 1.75 0 0.2 0 1 0 0 0 1 1.2 1.0\n";
  }
  const auto loaded = LoadSceneFile(path, &error);
  ASSERT_TRUE(loaded.has_value()) << error;
  EXPECT_EQ(loaded->rectangles().size(), 1u);
  std::remove(path.c_str());
}

TEST(SceneFile, ObjectsAppearDisappearAndMoveAlongTheirPath) {
  std::string error;
  const auto scene = ParseScene(
      "rect wall 3 0 1  0 1 0  0 0 1  4 2\n"
      "box person 2 1 0.5  0.4 0.4 1.0  path 0 2 1 0.5  2 2 -1 0.5\n"
      "box crate 1.5 0 0.25  0.5 0.5 0.5  from 1 until 3 untextured\n",
      &error);
  ASSERT_TRUE(scene.has_value()) << error;
  EXPECT_TRUE(scene->IsDynamic());
  EXPECT_FALSE(PaperBoardScene().IsDynamic());
  const auto centres = [](const Scene& s) {
    std::vector<Eigen::Vector3d> c;
    for (const Box& b : s.boxes()) c.push_back(b.T_world_box.translation());
    return c;
  };
  const Scene before = scene->At(-1.0), early = scene->At(0.5), middle = scene->At(1.0),
              late = scene->At(3.0);
  ASSERT_EQ(before.boxes().size(), 1u) << "the crate appears at 1 s";
  EXPECT_TRUE(centres(before)[0].isApprox(Eigen::Vector3d(2, 1, 0.5))) << "held before the path";
  ASSERT_EQ(early.boxes().size(), 1u);
  EXPECT_TRUE(centres(early)[0].isApprox(Eigen::Vector3d(2, 0.5, 0.5))) << "a quarter of the way";
  ASSERT_EQ(middle.boxes().size(), 2u);
  EXPECT_TRUE(centres(middle)[0].isApprox(Eigen::Vector3d(2, 0, 0.5)));
  EXPECT_FALSE(middle.boxes()[1].textured);
  ASSERT_EQ(late.boxes().size(), 1u) << "the crate is gone from 3 s";
  EXPECT_TRUE(centres(late)[0].isApprox(Eigen::Vector3d(2, -1, 0.5))) << "held after the path";
  EXPECT_EQ(late.rectangles().size(), 1u) << "static objects stay";
  // A beam along +x at the person's height meets the person only while it crosses y = 0.
  const Eigen::Vector3d origin(0, 0, 0.5), along_x(1, 0, 0);
  EXPECT_NEAR(middle.Raycast(origin, along_x, 10.0)->range_m, 1.25, 1e-9) << "the crate first";
  EXPECT_NEAR(scene->At(2.5).Raycast(origin, along_x, 10.0)->range_m, 1.25, 1e-9);
  EXPECT_NEAR(scene->At(0.9).Raycast(origin, along_x, 10.0)->range_m, 1.8, 1e-9) << "the person";
  EXPECT_NEAR(late.Raycast(origin, along_x, 10.0)->range_m, 3.0, 1e-9) << "the wall";

  for (const char* bad : {"box b 0 0 0 1 1 1 from\n", "box b 0 0 0 1 1 1 from 2 until 1\n",
                          "box b 0 0 0 1 1 1 path 1 0 0 0 0.5 1 1 1\n",
                          "box b 0 0 0 1 1 1 path 1 0 0\n", "box b 0 0 0 1 1 1 spin 3\n"}) {
    EXPECT_FALSE(ParseScene(bad, &error).has_value()) << bad;
    EXPECT_NE(error.find("line 1"), std::string::npos) << error;
  }
}

TEST(Simulator, CapturesTheSceneAsItIsAtTheFramesTime) {
  SimOptions options;
  options.add_noise = false;
  const SensorSpec spec = WithTessellation(*SensorPreset("sr3000"), 22, 18);
  std::string error;
  const auto scene = ParseScene(
      "rect wall 3 0 0  0 1 0  0 0 1  6 4\nbox crate 1.5 0 0  0.6 0.6 0.6  until 1\n", &error);
  ASSERT_TRUE(scene.has_value()) << error;
  RangeSimulator sim(*scene, spec, options);
  const Eigen::Isometry3d pose = ForwardLookingPose(Eigen::Vector3d::Zero());
  const auto centre_range = [&](const OrganizedCloud& c) {
    const std::size_t b = static_cast<std::size_t>(9 * 22 + 11);
    return c.true_range_m[b];
  };
  EXPECT_LT(centre_range(sim.Capture(pose, 0.5)), 1.5f) << "the crate, 1.2 m ahead";
  EXPECT_GT(centre_range(sim.Capture(pose, 1.0)), 2.9f) << "the crate is gone: the wall";
}

TEST(Simulator, NoiseFreeCloudIsExactInTheSensorFrame) {
  SimOptions options;
  options.add_noise = false;
  const SensorSpec spec = WithTessellation(*SensorPreset("sr3000"), 44, 36);
  RangeSimulator sim(PaperBoardScene(), spec, options);
  const auto cloud = sim.Capture(ForwardLookingPose(Eigen::Vector3d::Zero()));
  ASSERT_EQ(cloud.size(), 44u * 36u);
  EXPECT_EQ(cloud.rows, 36);
  std::size_t board = 0;
  std::size_t beyond = 0;
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    const float* p = &cloud.xyz[3 * i];
    if (cloud.beyond_range[i]) {
      ++beyond;
      EXPECT_NEAR(Eigen::Vector3d(p[0], p[1], p[2]).norm(), spec.r_max_m, 1e-4);
      continue;
    }
    ASSERT_TRUE(std::isfinite(p[0]));
    // Optical z is forward: board points have z = 1.75 exactly.
    if (std::abs(p[2] - 1.75f) < 1e-4f) ++board;
  }
  EXPECT_GT(board, cloud.size() / 2);
  EXPECT_GT(beyond, 0u);
}

TEST(Simulator, NoiseFollowsThePresetAndIsSeedable) {
  const SensorSpec spec = WithTessellation(*SensorPreset("stoc"), 16, 12);
  SimOptions options;
  options.seed = 42;
  RangeSimulator a(PaperBoardScene(), spec, options);
  RangeSimulator b(PaperBoardScene(), spec, options);
  const Eigen::Isometry3d pose = ForwardLookingPose(Eigen::Vector3d::Zero());
  EXPECT_EQ(a.Capture(pose).xyz, b.Capture(pose).xyz);
  // Centre beam hits the board head-on at 1.75 m: reading ~ N(q_mu, q_sigma^2).
  const std::size_t centre = *a.tessellation().BeamOf(Eigen::Vector3d(0.001, 0.001, 1.0));
  double sum = 0.0;
  double sq = 0.0;
  const int n = 4000;
  double true_range = 0.0;
  for (int i = 0; i < n; ++i) {
    const auto cloud = a.Capture(pose);
    const Eigen::Vector3d p(cloud.xyz[3 * centre], cloud.xyz[3 * centre + 1],
                            cloud.xyz[3 * centre + 2]);
    true_range = cloud.true_range_m[centre];
    sum += p.norm();
    sq += p.squaredNorm();
  }
  const double mean = sum / n;
  const double sd = std::sqrt(sq / n - mean * mean);
  EXPECT_NEAR(mean, spec.q_mu(true_range),
              0.001);  // stereo bias: ~1.93 m for 1.75 m
  EXPECT_GT(mean - true_range, 0.15);
  EXPECT_NEAR(sd, spec.q_sigma(true_range), 0.0006);
}

TEST(Simulator, DropoutTextureAndBeyondRange) {
  const SensorSpec spec = WithTessellation(*SensorPreset("sr3000"), 44, 36);
  SimOptions options;
  options.dropout_probability = 0.25;
  RangeSimulator sim(PaperBoardScene(), spec, options);
  const auto cloud = sim.Capture(ForwardLookingPose(Eigen::Vector3d::Zero()));
  std::size_t missing = 0;
  for (std::size_t i = 0; i < cloud.size(); ++i) missing += std::isnan(cloud.xyz[3 * i]) ? 1 : 0;
  EXPECT_NEAR(static_cast<double>(missing) / cloud.size(), 0.25, 0.05);

  SimOptions stereo;
  stereo.require_texture = true;
  stereo.flag_beyond_range = false;
  RangeSimulator stereo_sim(PaperBoardScene(), spec, stereo);
  const auto s = stereo_sim.Capture(ForwardLookingPose(Eigen::Vector3d::Zero()));
  for (std::size_t i = 0; i < s.size(); ++i) EXPECT_EQ(s.beyond_range[i], 0);
  // The untextured floor gives stereo no return: no point lies below the
  // board's bottom.
  for (std::size_t i = 0; i < s.size(); ++i) {
    if (!std::isnan(s.xyz[3 * i + 1])) {
      EXPECT_LT(s.xyz[3 * i + 1], 0.31f);  // y down
    }
  }
}

TEST(GroundTruth, LabelsFreeBeforeAndOccupiedAtTheSurface) {
  const Scene scene = PaperBoardScene();
  View view;
  view.spec = WithTessellation(*SensorPreset("sr3000"), 44, 36);
  view.T_world_sensor = ForwardLookingPose(Eigen::Vector3d::Zero());
  const VoxelLabels labels = LabelVoxels(scene, {view}, 0.02);
  auto label = [&](double x, double y, double z) {
    const auto it = labels.labels.find(KeyOfPoint(Eigen::Vector3d(x, y, z), 0.02));
    return it == labels.labels.end() ? -1 : (it->second ? 1 : 0);
  };
  EXPECT_EQ(label(1.75, 0.001, 0.001), 1);
  EXPECT_EQ(label(1.0, 0.001, 0.001), 0);
  EXPECT_EQ(label(0.3, 0.001, 0.001), -1);  // below r_min
  EXPECT_EQ(label(2.5, 0.001, 0.001), -1);  // behind the board
  EXPECT_GT(labels.CountOccupied(), 500u);
  EXPECT_GT(labels.CountFree(), 10 * labels.CountOccupied());
}

TEST(Experiment, PaperRunsAndOctoMapBaseline) {
  PaperRunOptions options;
  options.sr_frames = 1;
  options.stereo_frames = 1;
  const auto runs = PaperSensorRuns(options);
  ASSERT_EQ(runs.size(), 2u);
  EXPECT_EQ(runs[1].spec.cols, 160);
  EXPECT_NEAR(runs[1].T_world_sensor.translation().y(), 0.025, 1e-12);
  EXPECT_NEAR(runs[1].T_world_sensor.translation().z(), -0.080, 1e-12);
  const auto frames = SimulateRun(PaperBoardScene(), runs[0]);
  octomap::OcTree tree(0.05);
  InsertIntoOctoMap(frames[0], runs[0].T_world_sensor, runs[0].spec.r_max_m, &tree);
  const auto* node = tree.search(1.76, 0.01, 0.01);
  ASSERT_NE(node, nullptr);
  EXPECT_GT(node->getOccupancy(), 0.5);
}

}  // namespace
}  // namespace fusion::sim
