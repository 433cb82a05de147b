// BeamTessellation: azimuth x elevation grid over the FOV.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>
#include <stdexcept>
#include <string>

#include "fusion/core/beam_grid.h"

namespace fusion {
namespace {

TEST(TessellationTest, CountsAndWidths) {
  const BeamTessellation t(*SensorPreset("sr3000"));
  EXPECT_EQ(t.cols(), 176);
  EXPECT_EQ(t.rows(), 144);
  EXPECT_EQ(t.beam_count(), 176u * 144u);
  EXPECT_NEAR(t.beam_width_h_rad() * 176, SensorPreset("sr3000")->fov_h_rad, 1e-12);
  EXPECT_NEAR(t.beam_width_v_rad() * 144, SensorPreset("sr3000")->fov_v_rad, 1e-12);
}

TEST(TessellationTest, DirectionMapsBackToItsBeam) {
  for (const std::string name : {"sr3000", "stoc"}) {
    const BeamTessellation t(*SensorPreset(name));
    for (std::size_t b = 0; b < t.beam_count(); b += 97) {
      const Eigen::Vector3d d = t.Direction(b);
      EXPECT_NEAR(d.norm(), 1.0, 1e-12);
      EXPECT_EQ(t.BeamOf(d), b) << name << " beam " << b;
      EXPECT_EQ(t.BeamOf(3.7 * d), b);  // range does not matter
    }
  }
}

// Direction reads its centre lines from tables: bit for bit SubDirection's at offset 0, so a
// render's rays do not move.
TEST(TessellationTest, DirectionIsTheCentreSubDirectionExactly) {
  for (const std::string name : {"sr3000", "stoc", "laser_3d"}) {
    const BeamTessellation t(*SensorPreset(name));
    for (std::size_t b = 0; b < t.beam_count(); b += 13) {
      const Eigen::Vector3d d = t.Direction(b), s = t.SubDirection(b, 0.0, 0.0);
      ASSERT_EQ(d.x(), s.x()) << name << " beam " << b;
      ASSERT_EQ(d.y(), s.y()) << name << " beam " << b;
      ASSERT_EQ(d.z(), s.z()) << name << " beam " << b;
    }
    EXPECT_THROW(static_cast<void>(t.Direction(t.beam_count())), std::out_of_range);
  }
}

TEST(TessellationTest, OrientationColumnZeroLeftRowZeroTop) {
  const BeamTessellation t(*SensorPreset("sr3000"));
  const Eigen::Vector3d first = t.Direction(0);
  EXPECT_LT(first.x(), 0.0);  // left
  EXPECT_LT(first.y(), 0.0);  // top (y down)
  EXPECT_GT(first.z(), 0.0);
  const Eigen::Vector3d last = t.Direction(t.beam_count() - 1);
  EXPECT_GT(last.x(), 0.0);
  EXPECT_GT(last.y(), 0.0);
  // Optical axis lands in a centre beam.
  const std::optional<std::size_t> centre = t.BeamOf(Eigen::Vector3d(0, 0, 1));
  ASSERT_TRUE(centre.has_value());
  EXPECT_EQ(*centre / 176, 72u);
  EXPECT_EQ(*centre % 176, 88u);
}

TEST(TessellationTest, OutsideFovZeroAndNonFiniteGiveNoBeam) {
  const BeamTessellation t(*SensorPreset("sr3000"));
  EXPECT_FALSE(t.BeamOf(Eigen::Vector3d(0, 0, -1)).has_value());  // behind
  EXPECT_FALSE(t.BeamOf(Eigen::Vector3d(1, 0, 1)).has_value());   // 45 deg > 23.5
  EXPECT_FALSE(t.BeamOf(Eigen::Vector3d(0, -1, 1)).has_value());  // 45 deg up > 19.5
  EXPECT_FALSE(t.BeamOf(Eigen::Vector3d(0, 0, 0)).has_value());
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  EXPECT_FALSE(t.BeamOf(Eigen::Vector3d(nan, 0, 1)).has_value());
  EXPECT_FALSE(t.BeamOf(Eigen::Vector3d(0, 0, inf)).has_value());
  // Just inside the edges.
  const double h = 0.5 * SensorPreset("sr3000")->fov_h_rad - 1e-9;
  EXPECT_EQ(t.BeamOf(Eigen::Vector3d(std::sin(h), 0, std::cos(h))).value() % 176, 175u);
  EXPECT_EQ(t.BeamOf(Eigen::Vector3d(-std::sin(h), 0, std::cos(h))).value() % 176, 0u);
  EXPECT_THROW((void)t.Direction(t.beam_count()), std::out_of_range);
}

// BeamOf compares tangents against tables; BeamOfByAngles is the definition (atan2). They
// agree on every direction that is not within 1e-9 rad of a beam edge, inside and outside the
// FOV, for narrow and single-beam tessellations; a FOV of 180 degrees or more uses the angles.
TEST(TessellationTest, TangentTablesAgreeWithTheAngles) {
  SensorSpec one_column = *SensorPreset("stoc");
  one_column.cols = 1;
  one_column.rows = 3;
  SensorSpec wide = *SensorPreset("sr3000");
  wide.fov_h_rad = 4.7;  // a 270-degree scanner
  wide.cols = 540;
  for (const SensorSpec& spec : {*SensorPreset("sr3000"), *SensorPreset("stoc"), one_column, wide}) {
    const BeamTessellation t(spec);
    std::mt19937 rng(3);
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    const auto near_edge = [](double angle, double fov, int n) {
      const double w = fov / n;
      const double k = (angle + 0.5 * fov) / w;
      return std::abs(k - std::round(k)) * w < 1e-9;
    };
    int compared = 0, inside = 0;
    for (int i = 0; i < 200000; ++i) {
      // Directions in a cone a little wider than the FOV, at assorted ranges.
      const double az = 0.6 * spec.fov_h_rad * u(rng);
      const double el = 0.6 * spec.fov_v_rad * u(rng);
      const double r = 0.1 + 5.0 * (u(rng) + 1.0);
      const Eigen::Vector3d d(r * std::cos(el) * std::sin(az), -r * std::sin(el),
                              r * std::cos(el) * std::cos(az));
      if (near_edge(std::atan2(d.x(), d.z()), spec.fov_h_rad, spec.cols) ||
          near_edge(std::atan2(-d.y(), std::hypot(d.x(), d.z())), spec.fov_v_rad, spec.rows)) {
        continue;
      }
      ++compared;
      const auto fast = t.BeamOf(d);
      ASSERT_EQ(fast, t.BeamOfByAngles(d)) << spec.name << " " << d.transpose();
      inside += fast.has_value() ? 1 : 0;
    }
    EXPECT_GT(compared, 190000);
    EXPECT_GT(inside, compared / 2);       // most directions fall inside the FOV,
    EXPECT_LT(inside, compared * 9 / 10);  // and a good share outside
  }
}

// A 640 x 480 camera (the TUM intrinsics, principal point off centre): the point the camera
// sees at pixel (u, v) lies in beam (u, v), for every pixel, at the pixel's centre and near its
// corners; at stride 4 in beam (u / 4, v / 4).
TEST(PinholeTessellationTest, EveryPixelIsItsBeam) {
  const PinholeIntrinsics k{520.9, 521.0, 325.1, 249.7, 640, 480, 1};
  for (const int stride : {1, 4}) {
    SensorSpec spec = *SensorPreset("kinect_v1");
    PinholeIntrinsics ks = k;
    ks.stride = stride;
    SetPinhole(ks, &spec);
    ASSERT_EQ(ValidateSensorSpec(spec), "");
    const BeamTessellation t(spec);
    ASSERT_TRUE(t.pinhole());
    ASSERT_EQ(t.cols(), 640 / stride);
    ASSERT_EQ(t.rows(), 480 / stride);
    for (int v = 0; v < 480; ++v) {
      for (int u = 0; u < 640; ++u) {
        const std::size_t beam = static_cast<std::size_t>(v / stride) * t.cols() + u / stride;
        for (const double du : {0.0, -0.49, 0.49}) {
          const double depth_m = 0.5 + 0.01 * ((u + v) % 400);
          const Eigen::Vector3d p((u + du - k.cx_px) / k.fx_px * depth_m,
                                  (v - du - k.cy_px) / k.fy_px * depth_m, depth_m);
          ASSERT_EQ(t.BeamOf(p), beam) << u << ' ' << v << ' ' << du << " stride " << stride;
          ASSERT_EQ(t.BeamOfByAngles(p), beam) << u << ' ' << v << ' ' << du;
        }
      }
    }
    // Half a pixel beyond the image's edges: outside.
    EXPECT_FALSE(t.BeamOf({(-0.51 - k.cx_px) / k.fx_px, 0.0, 1.0}).has_value());
    EXPECT_FALSE(t.BeamOf({(639.51 - k.cx_px) / k.fx_px, 0.0, 1.0}).has_value());
    EXPECT_FALSE(t.BeamOf({0.0, (479.51 - k.cy_px) / k.fy_px, 1.0}).has_value());
    EXPECT_FALSE(t.BeamOf({0.0, 0.0, -1.0}).has_value());
  }
}

// Direction, SubDirection and BeamOf agree on every grid shape: a beam's centre line and the
// directions just inside its edges map back to it; an odd stride's last, narrower beam too.
TEST(PinholeTessellationTest, DirectionsMapBackToTheirBeams) {
  SensorSpec camera = *SensorPreset("kinect_v1");
  SetPinhole({400.0, 380.0, 150.2, 140.9, 301, 211, 7}, &camera);  // 43 x 31 beams, ragged
  SensorSpec scanner = *SensorPreset("laser_3d");
  SensorSpec turned = *SensorPreset("sr3000");
  turned.azimuth_centre_rad = 0.3;
  turned.elevation_centre_rad = -0.2;
  for (const SensorSpec& spec : {camera, scanner, turned}) {
    ASSERT_EQ(ValidateSensorSpec(spec), "") << spec.name;
    const BeamTessellation t(spec);
    for (std::size_t b = 0; b < t.beam_count(); b += 13) {
      EXPECT_NEAR(t.Direction(b).norm(), 1.0, 1e-12);
      EXPECT_EQ(t.BeamOf(2.5 * t.Direction(b)), b) << spec.name << " beam " << b;
      EXPECT_EQ(t.BeamOfByAngles(t.Direction(b)), b) << spec.name << " beam " << b;
      for (const double f : {-0.499, 0.499}) {
        EXPECT_EQ(t.BeamOf(t.SubDirection(b, f, 0.0)), b) << spec.name << " beam " << b;
        EXPECT_EQ(t.BeamOf(t.SubDirection(b, 0.0, f)), b) << spec.name << " beam " << b;
      }
    }
    // Column 0 is left and row 0 at the top; the last beam right and at the bottom.
    const auto azimuth = [](const Eigen::Vector3d& d) { return std::atan2(d.x(), d.z()); };
    EXPECT_LT(azimuth(t.SubDirection(0, -0.5, 0.0)), azimuth(t.SubDirection(0, 0.5, 0.0)));
    EXPECT_LT(t.SubDirection(0, 0.0, 0.5).y(), t.SubDirection(0, 0.0, -0.5).y());
  }
  const BeamTessellation t(camera);
  EXPECT_EQ(t.cols(), 43);
  EXPECT_EQ(t.rows(), 31);
  // The last column holds pixels 294..300: its centre line runs through pixel 297.
  const Eigen::Vector3d d = t.Direction(42);
  EXPECT_NEAR(400.0 * d.x() / d.z() + 150.2, 297.0, 1e-9);
}

// An asymmetric angular grid covers exactly its limits: a scanner seeing -8..33 degrees up and
// -92..92 across (wider than 180 degrees: no tangent tables, the angles decide).
TEST(AsymmetricTessellationTest, LimitsAreTheEdges) {
  const SensorSpec spec = *SensorPreset("laser_3d");
  const BeamTessellation t(spec);
  EXPECT_FALSE(t.HasTangentEdges());
  const double deg = 3.14159265358979323846 / 180.0;
  const auto at = [](double az, double el) {
    return Eigen::Vector3d(std::cos(el) * std::sin(az), -std::sin(el), std::cos(el) * std::cos(az));
  };
  EXPECT_EQ(t.BeamOf(at(-91.99 * deg, 32.99 * deg)), 0u);
  EXPECT_EQ(t.BeamOf(at(91.99 * deg, -7.99 * deg)), t.beam_count() - 1);
  EXPECT_FALSE(t.BeamOf(at(0.0, 33.01 * deg)).has_value());
  EXPECT_FALSE(t.BeamOf(at(0.0, -8.01 * deg)).has_value());
  EXPECT_FALSE(t.BeamOf(at(92.01 * deg, 0.0)).has_value());
  // A narrower asymmetric grid has tangent tables, and they agree with the angles.
  SensorSpec narrow = spec;
  SetAngularLimits(-20.0 * deg, 50.0 * deg, -8.0 * deg, 33.0 * deg, &narrow);
  narrow.cols = 280;
  const BeamTessellation n(narrow);
  ASSERT_TRUE(n.HasTangentEdges());
  for (int i = 0; i < 20000; ++i) {
    const double az = (-25.0 + 80.0 * (i % 200) / 199.0 + 0.0013) * deg;
    const double el = (-12.0 + 50.0 * (i / 200) / 99.0 + 0.0017) * deg;
    ASSERT_EQ(n.BeamOf(at(az, el)), n.BeamOfByAngles(at(az, el))) << az / deg << ' ' << el / deg;
  }
  // The field of view must stay within the sphere's coordinates.
  SensorSpec bad = narrow;
  bad.elevation_centre_rad = 1.4;
  EXPECT_NE(ValidateSensorSpec(bad), "");
  bad = narrow;
  bad.azimuth_centre_rad = 3.0;
  EXPECT_NE(ValidateSensorSpec(bad), "");
}

// The laser scan of OctoMap's sample data (180 x -7..+32 degrees): held symmetrically about the
// optical axis at 0.1 degree beams it needed 184 x 64.5 degrees, 1.19 M beams; the laser_3d
// preset's asymmetric grid (0.5 degree across, half the scanner's azimuth step; 0.02 degree up,
// a quarter of its sweeps' step) needs 64 % of the beams, five times as fine up.
TEST(AsymmetricTessellationTest, TheScanNeedsAFractionOfTheSymmetricGrid) {
  SensorSpec symmetric = *SensorPreset("laser_3d");
  const double deg = 3.14159265358979323846 / 180.0;
  SetAngularLimits(-92.0 * deg, 92.0 * deg, -32.25 * deg, 32.25 * deg, &symmetric);
  symmetric.cols = 1840;
  symmetric.rows = 645;
  const BeamTessellation before(symmetric);
  const BeamTessellation after(*SensorPreset("laser_3d"));
  EXPECT_LE(after.beam_count() * 3, before.beam_count() * 2);
  EXPECT_EQ(after.beam_count(), 368u * 2048u);
}


// A period's grid (SensorPeriods) reaches past the sensor's field of view: the sensor's beam
// (c, r) is the grown grid's (c + margin.cols, r + margin.rows), same direction, and every side
// moved out by at least the margin's angle.
TEST(WidenedFieldOfViewTest, KeepsEveryBeamAndGrowsEachSideByTheMargin) {
  SensorSpec off_centre = *SensorPreset("stoc");
  SetPinhole({200.0, 210.0, 70.3, 66.8, 158, 122, 2}, &off_centre);
  SensorSpec turned = *SensorPreset("sr3000");
  turned.azimuth_centre_rad = 0.07;
  turned.elevation_centre_rad = -0.09;
  const double margin_rad = 0.04;
  for (const SensorSpec& spec :
       {*SensorPreset("sr3000"), *SensorPreset("stoc"), off_centre, turned}) {
    SCOPED_TRACE(spec.name + (spec.pinhole ? " pinhole" : " angular"));
    BeamMargin m;
    const SensorSpec grown = WidenedFieldOfView(spec, margin_rad, &m);
    ASSERT_EQ(ValidateSensorSpec(grown), "");
    EXPECT_GT(m.cols, 0);
    EXPECT_GT(m.rows, 0);
    EXPECT_EQ(grown.cols, spec.cols + 2 * m.cols);
    EXPECT_EQ(grown.rows, spec.rows + 2 * m.rows);
    const BeamTessellation own(spec), wide(grown);
    for (int r = 0; r < own.rows(); r += 7) {
      for (int c = 0; c < own.cols(); c += 5) {
        const std::size_t b = static_cast<std::size_t>(r * own.cols() + c);
        const std::size_t w =
            static_cast<std::size_t>((r + m.rows) * wide.cols() + c + m.cols);
        ASSERT_LT((own.Direction(b) - wide.Direction(w)).norm(), 1e-9) << c << ", " << r;
        ASSERT_EQ(wide.BeamOf(own.Direction(b)), w);
      }
    }
    // The sensor's own beams, as a range of the grown grid, have the sensor's bounds.
    const auto a = own.InsetTangents(0.5);
    const auto in_wide = wide.InsetTangents(0.5, m.cols, m.cols + own.cols() - 1, m.rows,
                                            m.rows + own.rows() - 1);
    EXPECT_NEAR(in_wide.az_min, a.az_min, 1e-9);
    EXPECT_NEAR(in_wide.az_max, a.az_max, 1e-9);
    EXPECT_NEAR(in_wide.el_min, a.el_min, 1e-9);
    EXPECT_NEAR(in_wide.el_max, a.el_max, 1e-9);
    const auto edges = own.InsetTangents(0.0), wide_edges = wide.InsetTangents(0.0);
    EXPECT_GE(std::atan(edges.az_min) - std::atan(wide_edges.az_min), margin_rad - 1e-9);
    EXPECT_GE(std::atan(wide_edges.az_max) - std::atan(edges.az_max), margin_rad - 1e-9);
    EXPECT_GE(std::atan(edges.el_min) - std::atan(wide_edges.el_min), margin_rad - 1e-9);
    EXPECT_GE(std::atan(wide_edges.el_max) - std::atan(edges.el_max), margin_rad - 1e-9);
  }
}

// A strided image's clipped last beam is whole in the grown grid: it still holds what it held.
TEST(WidenedFieldOfViewTest, AClippedLastBeamHoldsWhatItHeld) {
  SensorSpec clipped = *SensorPreset("stoc");
  SetPinhole({200.0, 210.0, 70.3, 66.8, 157, 121, 2}, &clipped);
  BeamMargin m;
  const BeamTessellation own(clipped), wide(WidenedFieldOfView(clipped, 0.04, &m));
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-0.6, 0.6);
  for (int i = 0; i < 20000; ++i) {
    const Eigen::Vector3d d(u(rng), u(rng), 1.0);
    const auto b = own.BeamOf(d);
    if (!b) continue;
    const int c = static_cast<int>(*b % static_cast<std::size_t>(own.cols()));
    const int r = static_cast<int>(*b / static_cast<std::size_t>(own.cols()));
    ASSERT_EQ(wide.BeamOf(d),
              static_cast<std::size_t>((r + m.rows) * wide.cols() + c + m.cols));
  }
}

TEST(WidenedFieldOfViewTest, StaysShortOfNinetyDegreesAndWithinHalfTheGrid) {
  BeamMargin m;
  // The laser's azimuth reaches past 90 degrees already: only its elevation grows.
  const SensorSpec laser = *SensorPreset("laser_3d");
  const SensorSpec grown = WidenedFieldOfView(laser, 0.02, &m);
  EXPECT_EQ(m.cols, 0);
  EXPECT_GT(m.rows, 0);
  EXPECT_EQ(grown.fov_h_rad, laser.fov_h_rad);
  // A huge margin: at most half the beams a side, and never to 90 degrees.
  const SensorSpec sr = *SensorPreset("sr3000");
  const SensorSpec wide = WidenedFieldOfView(sr, 3.0, &m);
  EXPECT_LE(m.cols, sr.cols / 2);
  EXPECT_LE(m.rows, sr.rows / 2);
  EXPECT_LT(0.5 * wide.fov_h_rad, 1.5);
  const BeamTessellation t(wide);
  EXPECT_TRUE(t.HasTangentEdges());
  // No margin, no change.
  const SensorSpec same = WidenedFieldOfView(sr, 0.0, &m);
  EXPECT_EQ(m.cols, 0);
  EXPECT_EQ(m.rows, 0);
  EXPECT_EQ(same.cols, sr.cols);
}

}  // namespace
}  // namespace fusion
