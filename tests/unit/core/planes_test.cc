#include "fusion/core/planes.h"

#include <gtest/gtest.h>
#include <octomap/OcTree.h>

#include <cmath>
#include <functional>
#include <random>
#include <stdexcept>
#include <string>
#include <utility>

namespace fusion {
namespace {

constexpr double kDeg = HoughOptions::kDegree;
constexpr double kRes = 0.02;

void AddPlanePatch(octomap::OcTree* tree, const Eigen::Vector3d& center, const Eigen::Vector3d& u,
                   const Eigen::Vector3d& v, double half_u, double half_v, float log_odds) {
  for (double a = -half_u; a <= half_u; a += kRes / 2) {
    for (double b = -half_v; b <= half_v; b += kRes / 2) {
      const Eigen::Vector3d p = center + a * u + b * v;
      tree->setNodeValue(p.x(), p.y(), p.z(), log_odds, true);
    }
  }
}

double AngleDiff(double a, double b) {
  return std::abs(std::remainder(a - b, 2.0 * 3.14159265358979323846));
}

TEST(Planes, AnglesAndCanonicalForm) {
  const Plane p = CanonicalPlane(Eigen::Vector3d(-1, 0, 0), -1.75);
  EXPECT_NEAR(p.distance_m, 1.75, 1e-12);
  EXPECT_NEAR(p.phi_rad, 0.0, 1e-12);
  EXPECT_NEAR(p.theta_rad, 90 * kDeg, 1e-12);
  EXPECT_TRUE(NormalFromAngles(p.phi_rad, p.theta_rad).isApprox(p.normal));
  const Plane floor = CanonicalPlane(Eigen::Vector3d(0, 0, 1), -0.41);
  EXPECT_NEAR(floor.theta_rad, 180 * kDeg, 1e-9);
  EXPECT_NEAR(floor.distance_m, 0.41, 1e-12);
}

TEST(Planes, FindsBoardAndFloor) {
  octomap::OcTree tree(kRes);
  AddPlanePatch(&tree, {1.75, 0.0, 0.2}, Eigen::Vector3d::UnitY(), Eigen::Vector3d::UnitZ(), 0.6,
                0.5, 2.0f);
  AddPlanePatch(&tree, {1.4, 0.0, -0.41}, Eigen::Vector3d::UnitX(), Eigen::Vector3d::UnitY(), 0.3,
                0.7, 2.0f);
  // Free voxels do not vote.
  AddPlanePatch(&tree, {1.0, 0.0, 0.0}, Eigen::Vector3d::UnitY(), Eigen::Vector3d::UnitZ(), 0.5,
                0.5, -2.0f);
  tree.updateInnerOccupancy();
  const auto planes = DetectPlanes(tree);
  ASSERT_GE(planes.size(), 2u);
  const Plane& board = planes[0];
  EXPECT_NEAR(AngleDiff(board.phi_rad, 0.0), 0.0, 0.5 * kDeg);
  EXPECT_NEAR(board.theta_rad, 90 * kDeg, 0.5 * kDeg);
  EXPECT_NEAR(board.distance_m, 1.75,
              0.005);  // voxel centres of x in [1.74, 1.76]
  EXPECT_GT(board.support_voxels, 2500u);
  EXPECT_NEAR(board.extent.min().y(), -0.6, 0.03);
  EXPECT_NEAR(board.extent.max().z(), 0.7, 0.03);
  const Plane& floor = planes[1];
  EXPECT_NEAR(floor.theta_rad, 180 * kDeg, 0.5 * kDeg);
  EXPECT_NEAR(floor.distance_m, 0.41, 0.005);
}

// A floor 5 m from the world origin, thickened (three layers of voxels) and crossed by a ghost
// of itself tilted by 1.5 degrees (a frame whose pose was off) comes back as one plane; a table
// 0.7 m above it, parallel, stays a plane of its own. Judged at the support: 5 m out a
// 1.5-degree tilt moves the ghost's distance from the origin by 13 cm, more than the
// suppression distance.
TEST(Planes, AThickFloorAndItsTiltedGhostAreOnePlane) {
  octomap::OcTree tree(kRes);
  const Eigen::Vector3d x = Eigen::Vector3d::UnitX(), y = Eigen::Vector3d::UnitY();
  for (const double z : {0.0, 0.02, 0.04}) AddPlanePatch(&tree, {5.0, 0.0, z}, x, y, 1.5, 1.5, 2.0f);
  const double tilt = 1.5 * kDeg;
  const Eigen::Vector3d tilted_x(std::cos(tilt), 0.0, std::sin(tilt));
  AddPlanePatch(&tree, {5.0, 0.0, 0.02}, tilted_x, y, 1.5, 1.5, 1.0f);
  AddPlanePatch(&tree, {5.0, 0.0, 0.72}, x, y, 0.5, 0.4, 2.0f);
  tree.updateInnerOccupancy();
  const auto planes = DetectPlanes(tree);
  int floors = 0, tables = 0;
  for (const Plane& p : planes) {
    if (std::abs(p.normal.z()) < std::cos(10 * kDeg)) continue;
    const double height = p.distance_m / p.normal.z() - p.normal.x() / p.normal.z() * 5.0;
    floors += std::abs(height - 0.02) < 0.1 ? 1 : 0;
    tables += std::abs(height - 0.72) < 0.1 ? 1 : 0;
  }
  EXPECT_EQ(floors, 1);
  EXPECT_EQ(tables, 1);
  // The floor is the strongest, level within a degree (the ghost's voxels are a quarter).
  ASSERT_FALSE(planes.empty());
  EXPECT_GT(std::abs(planes[0].normal.z()), std::cos(1.0 * kDeg));
}

TEST(Planes, TiltedPlaneAndRegion) {
  octomap::OcTree tree(kRes);
  const Eigen::Vector3d n = NormalFromAngles(30 * kDeg, 60 * kDeg);
  const Eigen::Vector3d u = n.cross(Eigen::Vector3d::UnitZ()).normalized();
  const Eigen::Vector3d v = n.cross(u).normalized();
  AddPlanePatch(&tree, 2.0 * n, u, v, 0.6, 0.6, 1.5f);
  AddPlanePatch(&tree, {-2.0, 0.0, 0.0}, Eigen::Vector3d::UnitY(), Eigen::Vector3d::UnitZ(), 0.5,
                0.5, 1.5f);
  tree.updateInnerOccupancy();
  HoughOptions options;
  options.region = Eigen::AlignedBox3d(Eigen::Vector3d(0, -5, -5), Eigen::Vector3d(5, 5, 5));
  const auto planes = DetectPlanes(tree, options);
  ASSERT_EQ(planes.size(), 1u);
  EXPECT_NEAR(AngleDiff(planes[0].phi_rad, 30 * kDeg), 0.0, 1.0 * kDeg);
  EXPECT_NEAR(planes[0].theta_rad, 60 * kDeg, 1.0 * kDeg);
  EXPECT_NEAR(planes[0].distance_m, 2.0, 0.015);
}

// The planes of a search whose candidates are refined on merged voters (the default) are those
// of a search that votes and refines with every voxel alone: a board, a floor and a tilted
// panel, each within 0.3 degree and 3 mm.
TEST(Planes, RefiningOnMergedVotersFindsThePlanesOfTheVoxels) {
  octomap::OcTree tree(kRes);
  AddPlanePatch(&tree, {1.75, 0.0, 0.2}, Eigen::Vector3d::UnitY(), Eigen::Vector3d::UnitZ(), 0.6,
                0.5, 2.0f);
  AddPlanePatch(&tree, {1.4, 0.0, -0.41}, Eigen::Vector3d::UnitX(), Eigen::Vector3d::UnitY(), 0.5,
                0.9, 2.0f);
  const Eigen::Vector3d n = NormalFromAngles(-40 * kDeg, 70 * kDeg);
  const Eigen::Vector3d u = n.cross(Eigen::Vector3d::UnitZ()).normalized();
  AddPlanePatch(&tree, 2.5 * n, u, n.cross(u).normalized(), 0.4, 0.4, 1.0f);
  tree.updateInnerOccupancy();
  HoughOptions every_voxel;
  every_voxel.vote_merge_voxels = 1;
  every_voxel.vote_cube_min_m = 0.0;
  const auto fine = DetectPlanes(tree, every_voxel);
  const auto merged = DetectPlanes(tree);
  ASSERT_EQ(fine.size(), 3u);
  ASSERT_EQ(merged.size(), 3u);
  for (std::size_t i = 0; i < fine.size(); ++i) {
    EXPECT_GT(fine[i].normal.dot(merged[i].normal), std::cos(0.3 * kDeg)) << i;
    EXPECT_NEAR(fine[i].distance_m, merged[i].distance_m, 0.003) << i;
    EXPECT_NEAR(static_cast<double>(fine[i].support_voxels),
                static_cast<double>(merged[i].support_voxels), 0.02 * fine[i].support_voxels)
        << i;
  }
}

// A wall 8 m from the origin, tilted 20 degrees from vertical and two voxels thick: one plane,
// where the wall is. Far out a small tilt moves the distance from the origin a lot; the vote
// cubes (16 cm) and the refinement on them keep it one plane.
TEST(Planes, ATiltedThickPlaneFarFromTheOriginIsOnePlane) {
  octomap::OcTree tree(kRes);
  const Eigen::Vector3d n = NormalFromAngles(150 * kDeg, 110 * kDeg);
  const Eigen::Vector3d u = n.cross(Eigen::Vector3d::UnitZ()).normalized();
  const Eigen::Vector3d v = n.cross(u).normalized();
  for (const double offset : {0.0, 0.02}) {
    AddPlanePatch(&tree, (8.0 + offset) * n, u, v, 1.5, 1.0, 2.0f);
  }
  tree.updateInnerOccupancy();
  const auto planes = DetectPlanes(tree);
  int copies = 0;
  for (const Plane& p : planes) {
    if (std::abs(p.normal.dot(n)) > std::cos(10 * kDeg)) ++copies;
  }
  EXPECT_EQ(copies, 1);
  ASSERT_FALSE(planes.empty());
  EXPECT_GT(planes[0].normal.dot(n), std::cos(0.5 * kDeg));
  EXPECT_NEAR(planes[0].distance_m, 8.01, 0.01);
}

// Coarse to fine (the default at 2 cm: every normal voted by 16 cm cubes, the strong normals
// again by 8 cm cubes) finds the planes of a single vote by the 8 cm cubes: a floor 6 m out,
// warped (two halves 3 cm apart, one tilted by a degree), and a wall.
TEST(Planes, CoarseToFineFindsThePlanesOfTheFineVote) {
  octomap::OcTree tree(kRes);
  const Eigen::Vector3d x = Eigen::Vector3d::UnitX(), y = Eigen::Vector3d::UnitY();
  const double tilt = 1.0 * kDeg;
  AddPlanePatch(&tree, {6.0, -1.0, 0.01}, x, y, 1.5, 1.0, 2.0f);
  AddPlanePatch(&tree, {6.0, 1.0, 0.04}, Eigen::Vector3d(std::cos(tilt), 0.0, std::sin(tilt)), y,
                1.5, 1.0, 1.0f);
  AddPlanePatch(&tree, {7.6, 0.0, 1.0}, y, Eigen::Vector3d::UnitZ(), 2.0, 0.9, 2.0f);
  tree.updateInnerOccupancy();
  HoughOptions one_vote;
  one_vote.vote_cube_min_m = 0.0;
  const auto fine = DetectPlanes(tree, one_vote);
  const auto coarse_to_fine = DetectPlanes(tree);
  ASSERT_FALSE(fine.empty());
  ASSERT_EQ(coarse_to_fine.size(), fine.size());
  for (std::size_t i = 0; i < fine.size(); ++i) {
    EXPECT_GT(fine[i].normal.dot(coarse_to_fine[i].normal), std::cos(0.1 * kDeg)) << i;
    EXPECT_NEAR(fine[i].distance_m, coarse_to_fine[i].distance_m, 0.002) << i;
    EXPECT_EQ(fine[i].support_voxels, coarse_to_fine[i].support_voxels) << i;
  }
}

// The plane of a two-layer slab lies nearer the layer with more evidence: the voxels are fitted
// by their log-odds above the voting threshold, not by p(m), which is near 1 for both a voxel
// seen once and one seen a hundred times.
TEST(Planes, TheRefinementWeighsVoxelsByTheirEvidence) {
  octomap::OcTree tree(kRes);
  const Eigen::Vector3d x = Eigen::Vector3d::UnitX(), y = Eigen::Vector3d::UnitY();
  AddPlanePatch(&tree, {2.0, 0.0, 0.01}, x, y, 1.0, 1.0, 4.0f);   // p = 0.982
  AddPlanePatch(&tree, {2.0, 0.0, 0.03}, x, y, 1.0, 1.0, 0.4f);   // p = 0.599
  tree.updateInnerOccupancy();
  const auto planes = DetectPlanes(tree);
  ASSERT_FALSE(planes.empty());
  EXPECT_GT(std::abs(planes[0].normal.z()), std::cos(0.5 * kDeg));
  const double height = planes[0].distance_m / std::abs(planes[0].normal.z());
  // By evidence: 0.01 + 0.02 * 0.4 / 4.4 = 0.0118 m; by p(m): 0.01 + 0.02 * 0.599 / 1.581 = 0.0176.
  EXPECT_NEAR(height, 0.0118, 0.001);
}

octomap::OcTree BoardTree() {
  octomap::OcTree tree(kRes);
  AddPlanePatch(&tree, {1.75, 0.0, 0.2}, Eigen::Vector3d::UnitY(), Eigen::Vector3d::UnitZ(), 0.6,
                0.5, 2.0f);
  tree.updateInnerOccupancy();
  return tree;
}

TEST(Planes, AnAccumulatorOverTheBoundIsRefusedBeforeItIsBuilt) {
  const octomap::OcTree tree = BoardTree();
  HoughOptions options;
  const PlaneSearch free_search = SearchPlanes(tree, options);
  ASSERT_EQ(free_search.status, PlaneSearchStatus::kOk);
  ASSERT_FALSE(free_search.planes.empty());
  EXPECT_GT(free_search.voters, 2500u);
  // 180 x 90 normals; the board is within 2 m: (floor(max |p| / 2 cm) + 2 + 3) cells per normal.
  EXPECT_GE(free_search.accumulator_cells, 180u * 90u * (87u + 5u));
  options.max_accumulator_cells = free_search.accumulator_cells;
  EXPECT_EQ(SearchPlanes(tree, options).status, PlaneSearchStatus::kOk);
  options.max_accumulator_cells = free_search.accumulator_cells - 1;
  const PlaneSearch refused = SearchPlanes(tree, options);
  EXPECT_EQ(refused.status, PlaneSearchStatus::kTooLarge);
  EXPECT_TRUE(refused.planes.empty());
  EXPECT_EQ(refused.accumulator_cells, free_search.accumulator_cells);
}

TEST(Planes, AStopRequestEndsTheSearchInEveryPhase) {
  const octomap::OcTree tree = BoardTree();
  HoughOptions options;
  // Every voxel votes alone: the board's 3 000 voxels make dozens of polls (merged into cubes,
  // the whole search is two).
  options.vote_merge_voxels = 1;
  options.vote_cube_min_m = 0.0;
  int polls = 0;
  options.stop = [&polls] { return ++polls > 1000000; };
  ASSERT_EQ(SearchPlanes(tree, options).status, PlaneSearchStatus::kOk);
  const int polls_in_full_search = polls;
  ASSERT_GT(polls_in_full_search, 4);
  // Stopping at each poll of the full search ends it there: nothing found, status kStopped.
  for (int stop_at : {1, polls_in_full_search / 3, polls_in_full_search - 1}) {
    polls = 0;
    options.stop = [&polls, stop_at] { return ++polls >= stop_at; };
    const PlaneSearch search = SearchPlanes(tree, options);
    EXPECT_EQ(search.status, PlaneSearchStatus::kStopped) << stop_at;
    EXPECT_TRUE(search.planes.empty());
    EXPECT_EQ(polls, stop_at) << "the search went on after being told to stop";
  }
}

TEST(Planes, OptionsOutsideTheirRangeAreNamedAndRefused) {
  EXPECT_TRUE(HoughOptions{}.IsValid());
  const std::pair<std::function<void(HoughOptions*)>, std::string> cases[] = {
      {[](HoughOptions* o) { o->phi_bin_rad = 0.0; }, "phi_bin_rad"},
      {[](HoughOptions* o) { o->theta_bin_rad = std::nan(""); }, "theta_bin_rad"},
      {[](HoughOptions* o) { o->d_bin_m = -0.01; }, "d_bin_m"},
      {[](HoughOptions* o) { o->min_probability = 1.0; }, "min_probability"},
      {[](HoughOptions* o) { o->max_planes = 0; }, "max_planes"},
      {[](HoughOptions* o) { o->nms_angle_rad = -1.0; }, "nms_angle_rad"},
      {[](HoughOptions* o) { o->nms_distance_m = INFINITY; }, "nms_distance_m"},
      {[](HoughOptions* o) { o->support_distance_m = -0.1; }, "support_distance_m"},
      {[](HoughOptions* o) { o->refine_iterations = -1; }, "refine_iterations"},
      {[](HoughOptions* o) { o->vote_merge_voxels = 0; }, "vote_merge_voxels"},
      {[](HoughOptions* o) { o->vote_cube_min_m = -0.1; }, "vote_cube_min_m"},
      {[](HoughOptions* o) {
         o->region = Eigen::AlignedBox3d(Eigen::Vector3d(1, 0, 0), Eigen::Vector3d(0, 1, 1));
       },
       "region"},
  };
  octomap::OcTree tree(0.05);
  for (const auto& [spoil, field] : cases) {
    HoughOptions options;
    spoil(&options);
    std::string why;
    EXPECT_FALSE(options.IsValid(&why)) << field;
    EXPECT_EQ(why.rfind(field, 0), 0u) << field << " gave: " << why;
    EXPECT_THROW((void)SearchPlanes(tree, options), std::invalid_argument) << field;
  }
}

TEST(Planes, EmptyTreeGivesNoPlanes) {
  octomap::OcTree tree(kRes);
  EXPECT_TRUE(DetectPlanes(tree).empty());
}

}  // namespace
}  // namespace fusion
