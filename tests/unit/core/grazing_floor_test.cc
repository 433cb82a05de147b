// A laser a few centimetres above a floor sees it at a degree or two: the ranges of
// neighbouring beams grow as a progression, steps far beyond the shallowest incidence the render
// follows (3 degrees), and a beam holds readings metres apart. The floor still comes back as a
// surface (beam_trace.cc, SurfaceStep), while a depth edge (one jump between neighbours that
// agree) is not bridged. BENCHMARKS.md, "The laser scan's floor".
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <vector>

#include "fusion/core/world_map.h"

namespace fusion {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kResolutionM = 0.05;

double Rad(double deg) { return deg * kPi / 180.0; }

// The point `range_m` along azimuth az (x right) and elevation el (up; the optical frame's y
// points down).
void AddPoint(double az_deg, double el_deg, double range_m, std::vector<float>* xyz) {
  const double az = Rad(az_deg), el = Rad(el_deg);
  xyz->push_back(static_cast<float>(range_m * std::cos(el) * std::sin(az)));
  xyz->push_back(static_cast<float>(-range_m * std::sin(el)));
  xyz->push_back(static_cast<float>(range_m * std::cos(el) * std::cos(az)));
}

WorldMapOptions Options() {
  WorldMapOptions options;
  options.resolution_m = kResolutionM;
  options.render.resolution_m = kResolutionM;
  return options;
}

// The map of one scan `xyz` taken at the origin by the laser_3d preset with `rows` beams up
// over its 41 degrees (0: the preset's).
void Map(const std::vector<float>& xyz, int rows, WorldMap* map) {
  SensorSpec laser = *SensorPreset("laser_3d");
  if (rows > 0) laser.rows = rows;
  EXPECT_EQ(map->AddSensor("laser", laser), MapStatus::kOk);
  EXPECT_EQ(map->Integrate("laser", Eigen::Isometry3d::Identity(), xyz.data(), xyz.size() / 3),
            MapStatus::kOk);
  EXPECT_EQ(map->Render("laser"), MapStatus::kOk);
}

// Whether a voxel within one voxel of p is occupied (p >= 0.55, the service's threshold).
bool OccupiedNear(const WorldMap& map, const Eigen::Vector3d& p) {
  for (int dx = -1; dx <= 1; ++dx) {
    for (int dy = -1; dy <= 1; ++dy) {
      for (int dz = -1; dz <= 1; ++dz) {
        const auto o = map.Occupancy(p + kResolutionM * Eigen::Vector3d(dx, dy, dz));
        if (o && *o >= 0.55) return true;
      }
    }
  }
  return false;
}

// The scanner 8 cm above a floor rolled by a degree, sweeps every 0.08 degrees down from -0.5
// to -4 degrees, a reading every degree across +-20 degrees: the floor from 1 to 6 m. With
// 0.5-degree beams up (82 rows) a beam holds six sweeps, up to a metre apart, and its
// neighbours' ranges differ by up to three times what 3 degrees of incidence allow; followed as
// one surface (without the progression rule 77 % of the points), and so on the preset's grid.
TEST(GrazingFloorTest, AFloorSeenAtADegreeIsOccupiedWhereItsPointsLie) {
  const double height_m = 0.08, roll = Rad(1.0);
  std::vector<float> xyz;
  for (double el = -0.5; el >= -4.0; el -= 0.08) {
    for (double az = -20.0; az <= 20.0; az += 1.0) {
      const double a = Rad(az), e = Rad(el);
      // The ray's run towards the floor's normal (the optical frame's y points down).
      const double down =
          -std::sin(e) * std::cos(roll) + std::cos(e) * std::sin(a) * std::sin(roll);
      if (down <= 0.0 || height_m / down > 6.0) continue;
      AddPoint(az, el, height_m / down, &xyz);
    }
  }
  for (const int rows : {82, 0}) {
    WorldMap map(Options());
    Map(xyz, rows, &map);
    int near = 0, points = 0;
    for (std::size_t i = 0; i < xyz.size(); i += 3) {
      const Eigen::Vector3d p(xyz[i], xyz[i + 1], xyz[i + 2]);
      if (p.norm() < 2.0 || p.norm() > 5.0 || std::abs(p.x()) > 1.0) continue;
      ++points;
      if (OccupiedNear(map, p)) ++near;
    }
    ASSERT_GT(points, 100);
    const double share = static_cast<double>(near) / points;
    std::printf(
        "%d rows (0: the preset's): floor points 2-5 m near an occupied voxel: %.1f %% of "
        "%d\n",
        rows, 100.0 * share, points);
    EXPECT_GE(share, 0.95) << rows << " rows";
  }
}

// A wall at 3 m beside a wall at 6 m (the edge at azimuth 0): the 3 m between them at the edge
// stays unoccupied, each wall occupied.
TEST(GrazingFloorTest, ADepthEdgeIsNotBridged) {
  std::vector<float> xyz;
  for (double el = -5.0; el <= 5.0; el += 0.08) {
    for (double az = -10.0; az <= 10.0; az += 0.25) {
      const double depth_m = az < 0.0 ? 3.0 : 6.0;
      const double range_m = depth_m / (std::cos(Rad(el)) * std::cos(Rad(az)));
      AddPoint(az, el, range_m, &xyz);
    }
  }
  WorldMap map(Options());
  Map(xyz, 0, &map);
  EXPECT_TRUE(OccupiedNear(map, {-0.1, 0.0, 3.0}));
  EXPECT_TRUE(OccupiedNear(map, {0.2, 0.0, 6.0}));
  int bridged = 0;
  for (double z = 3.3; z <= 5.7; z += kResolutionM) {
    for (double x = -0.05; x <= 0.05; x += kResolutionM) {
      const auto o = map.Occupancy({x, 0.0, z});
      if (o && *o > 0.5) ++bridged;
    }
  }
  EXPECT_EQ(bridged, 0);
}

}  // namespace
}  // namespace fusion
