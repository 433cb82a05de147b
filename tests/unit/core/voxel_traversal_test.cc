#include "fusion/core/voxel_traversal.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <cstdlib>
#include <random>
#include <set>
#include <tuple>
#include <vector>

#include "fusion/core/local_grid.h"

namespace fusion {
namespace {

using Index = std::tuple<long, long, long>;

constexpr double kRes = 0.02;

std::vector<Index> Walk(const Eigen::Vector3d& origin, const Eigen::Vector3d& dir, double t0,
                        double t1, double res = kRes) {
  std::vector<Index> visited;
  ForEachVoxel(origin, dir, t0, t1, res, [&](const VoxelTraversal& v) {
    visited.emplace_back(v.index(0), v.index(1), v.index(2));
  });
  return visited;
}

// Oracle, slow and obvious: the voxels of points sampled densely along the segment [t0, t1)
// (every voxel the segment crosses for more than the sample step must be among them). The end is
// left out: a walk to t1 does not enter a voxel whose face lies at t1.
std::set<Index> Sampled(const Eigen::Vector3d& origin, const Eigen::Vector3d& dir, double t0,
                        double t1, double res = kRes) {
  std::set<Index> voxels;
  const double inv_res = 1.0 / res;  // a point's voxel as KeyOfPoint (and the map) floors it
  const double step = res * 1e-3;
  for (long i = 0;; ++i) {
    const double t = t0 + static_cast<double>(i) * step;
    if (t >= t1) break;
    const Eigen::Vector3d p = origin + dir * t;
    voxels.emplace(static_cast<long>(std::floor(p.x() * inv_res)),
                   static_cast<long>(std::floor(p.y() * inv_res)),
                   static_cast<long>(std::floor(p.z() * inv_res)));
  }
  return voxels;
}

// Whether the segment touches the closed box of voxel v (grown by `slack` metres): slab test.
bool Touches(const Index& v, const Eigen::Vector3d& origin, const Eigen::Vector3d& dir, double t0,
             double t1, double slack, double res = kRes) {
  const long idx[3] = {std::get<0>(v), std::get<1>(v), std::get<2>(v)};
  double lo = t0, hi = t1;
  for (int a = 0; a < 3; ++a) {
    const double box_lo = static_cast<double>(idx[a]) * res - slack;
    const double box_hi = static_cast<double>(idx[a] + 1) * res + slack;
    if (dir[a] == 0.0) {
      if (origin[a] < box_lo || origin[a] > box_hi) return false;
      continue;
    }
    double ta = (box_lo - origin[a]) / dir[a], tb = (box_hi - origin[a]) / dir[a];
    if (ta > tb) std::swap(ta, tb);
    lo = std::max(lo, ta);
    hi = std::min(hi, tb);
  }
  return lo <= hi;
}

// The walk against the oracles: it visits every sampled voxel, each voxel once, every voxel it
// visits touches the segment, and consecutive voxels are face neighbours.
void ExpectMatchesOracle(const Eigen::Vector3d& origin, const Eigen::Vector3d& dir, double t0,
                         double t1) {
  SCOPED_TRACE(::testing::Message() << "origin " << origin.transpose() << " dir " << dir.transpose()
                                    << " t " << t0 << ".." << t1);
  const std::vector<Index> walk = Walk(origin, dir, t0, t1);
  ASSERT_FALSE(walk.empty());
  const std::set<Index> visited(walk.begin(), walk.end());
  EXPECT_EQ(visited.size(), walk.size()) << "a voxel visited twice";
  for (const Index& v : Sampled(origin, dir, t0, t1)) {
    EXPECT_TRUE(visited.count(v)) << "sampled voxel " << std::get<0>(v) << " " << std::get<1>(v)
                                  << " " << std::get<2>(v) << " not visited";
  }
  for (const Index& v : walk) {
    EXPECT_TRUE(Touches(v, origin, dir, t0, t1, 1e-12)) << "visited voxel off the segment";
  }
  for (std::size_t i = 1; i < walk.size(); ++i) {
    const long d = std::abs(std::get<0>(walk[i]) - std::get<0>(walk[i - 1])) +
                   std::abs(std::get<1>(walk[i]) - std::get<1>(walk[i - 1])) +
                   std::abs(std::get<2>(walk[i]) - std::get<2>(walk[i - 1]));
    EXPECT_EQ(d, 1) << "step " << i << " is not to a face neighbour";
  }
}

TEST(VoxelTraversal, AxisAlignedRaysVisitTheRowOfVoxels) {
  // Along +x from the middle of voxel (0, 0, 0) to the middle of voxel (9, 0, 0).
  const Eigen::Vector3d origin(0.5 * kRes, 0.5 * kRes, 0.5 * kRes);
  std::vector<Index> expected;
  for (long i = 0; i < 10; ++i) expected.emplace_back(i, 0, 0);
  EXPECT_EQ(Walk(origin, Eigen::Vector3d::UnitX(), 0.0, 9.0 * kRes), expected);
  // Along -z: indices fall below zero.
  expected.clear();
  for (long i = 0; i > -10; --i) expected.emplace_back(0, 0, i);
  EXPECT_EQ(Walk(origin, -Eigen::Vector3d::UnitZ(), 0.0, 9.0 * kRes), expected);
  for (int a = 0; a < 3; ++a) {
    ExpectMatchesOracle(origin, Eigen::Vector3d::Unit(a), 0.0, 0.37);
    ExpectMatchesOracle(origin, -Eigen::Vector3d::Unit(a), 0.01, 0.5);
  }
}

TEST(VoxelTraversal, DiagonalRaysMatchTheSampledOracle) {
  std::mt19937 rng(16);
  std::uniform_real_distribution<double> coordinate(-0.3, 0.3);
  std::normal_distribution<double> normal(0.0, 1.0);
  for (int trial = 0; trial < 200; ++trial) {
    const Eigen::Vector3d origin(coordinate(rng), coordinate(rng), coordinate(rng));
    const Eigen::Vector3d dir = Eigen::Vector3d(normal(rng), normal(rng), normal(rng)).normalized();
    ExpectMatchesOracle(origin, dir, 0.05, 0.05 + 0.5 * std::abs(coordinate(rng)) + 0.01);
  }
  // The main diagonal through voxel corners from inside a voxel.
  ExpectMatchesOracle(Eigen::Vector3d::Constant(0.3 * kRes), Eigen::Vector3d::Ones().normalized(),
                      0.0, 0.4);
}

TEST(VoxelTraversal, RaysOnVoxelFacesAndThroughCornersStayOnOneSide) {
  // A ray in the plane y = 0 (a face between voxel rows -1 and 0) runs in row 0: the face
  // belongs to the voxel above it, as floor() says.
  const Eigen::Vector3d on_face(0.5 * kRes, 0.0, 0.5 * kRes);
  for (const Index& v : Walk(on_face, Eigen::Vector3d::UnitX(), 0.0, 0.2)) {
    EXPECT_EQ(std::get<1>(v), 0);
    EXPECT_EQ(std::get<2>(v), 0);
  }
  ExpectMatchesOracle(on_face, Eigen::Vector3d::UnitX(), 0.0, 0.2);
  // Along an edge (y = z = 0): row (0, 0).
  const Eigen::Vector3d on_edge(0.5 * kRes, 0.0, 0.0);
  for (const Index& v : Walk(on_edge, -Eigen::Vector3d::UnitX(), 0.0, 0.2)) {
    EXPECT_EQ(std::get<1>(v), 0);
    EXPECT_EQ(std::get<2>(v), 0);
  }
  // Starting exactly on a face, moving away from it and toward it.
  ExpectMatchesOracle(Eigen::Vector3d(kRes, 0.5 * kRes, 0.5 * kRes), Eigen::Vector3d::UnitX(), 0.0,
                      0.1);
  ExpectMatchesOracle(Eigen::Vector3d(kRes, 0.5 * kRes, 0.5 * kRes), -Eigen::Vector3d::UnitX(), 0.0,
                      0.1);
  // Through voxel corners in the xy plane: the walk steps around each corner through one of
  // the two voxels that touch it, never diagonally.
  ExpectMatchesOracle(Eigen::Vector3d(0.0, 0.0, 0.5 * kRes),
                      Eigen::Vector3d(1.0, 1.0, 0.0).normalized(), 0.0, 0.2);
  // Ending exactly on a face: the voxel beyond it is not entered (quarter-metre voxels, so
  // that the face ranges are exact in binary).
  const double res = 0.25;
  const std::vector<Index> to_face =
      Walk(Eigen::Vector3d::Constant(0.5 * res), Eigen::Vector3d::UnitX(), 0.0, 2.5 * res, res);
  ASSERT_EQ(to_face.size(), 3u);
  EXPECT_EQ(to_face.back(), Index(2, 0, 0));
}

TEST(VoxelTraversal, EntryRangeIsWhereTheRayEntersItsFirstVoxel) {
  const Eigen::Vector3d origin(0.0, 0.0, 0.5 * kRes);
  // At t_first = 0.05 the ray along +x is in voxel 2, entered at 0.04.
  const VoxelTraversal walk(origin, Eigen::Vector3d::UnitX(), 0.05, kRes);
  EXPECT_EQ(walk.index(0), 2);
  EXPECT_NEAR(walk.EntryRange(), 0.04, 1e-12);
  EXPECT_NEAR(walk.ExitRange(walk.NextAxis()), 0.06, 1e-12);
  // Going -x, voxel -3 ([-0.06, -0.04)) is entered at 0.04.
  const VoxelTraversal back(origin, -Eigen::Vector3d::UnitX(), 0.05, kRes);
  EXPECT_EQ(back.index(0), -3);
  EXPECT_NEAR(back.EntryRange(), 0.04, 1e-12);
}

TEST(VoxelTraversal, KeysAreOctoMapsAndTheWalkStopsAtTheKeyRange) {
  const Eigen::Vector3d p(0.123, -4.56, 7.89);
  const VoxelTraversal walk(p, Eigen::Vector3d::UnitX(), 0.0, kRes);
  EXPECT_EQ(walk.Key(), KeyOfPoint(p, kRes));
  // A ray that starts beyond the key range visits nothing.
  const double edge_m = MapHalfExtentM(kRes);
  EXPECT_TRUE(
      Walk(Eigen::Vector3d(edge_m + 0.01, 0.0, 0.0), -Eigen::Vector3d::UnitX(), 0.0, 1.0).empty());
  // One that leaves it stops in the last voxel with a key (index 32767).
  const std::vector<Index> out =
      Walk(Eigen::Vector3d(edge_m - 0.05, 0.01, 0.01), Eigen::Vector3d::UnitX(), 0.0, 1.0);
  ASSERT_FALSE(out.empty());
  EXPECT_EQ(std::get<0>(out.back()), kMapKeyOffset - 1);
  EXPECT_LT(out.size(), 5u);
}

}  // namespace
}  // namespace fusion
