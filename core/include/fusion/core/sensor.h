// Sensor descriptions: range limits, field of view, forward-model polynomials.
//
// Frames: the sensor frame is the camera optical frame: x right, y down, z forward.
// Units: metres and radians in every API; the paper's tables (mm) are converted once here.
#pragma once

#include <Eigen/Core>
#include <optional>
#include <string>
#include <vector>

namespace fusion {

// q(r) = a2 r^2 + a1 r + a0, r and q in metres.
struct Polynomial2 {
  double a2 = 0.0;
  double a1 = 0.0;
  double a0 = 0.0;
  [[nodiscard]] double operator()(double r_m) const { return (a2 * r_m + a1) * r_m + a0; }
  // Converts a polynomial fitted in millimetres (paper Table II) to metres.
  [[nodiscard]] static Polynomial2 FromMillimetres(double a2_per_mm, double a1, double a0_mm) {
    return {a2_per_mm * 1000.0, a1, a0_mm / 1000.0};
  }
};

enum class ForwardModelKind { kPaper3d, kClassicBeam };

// Parameters of the classic beam model (Probabilistic Robotics, Sec. 6.3).
struct ClassicBeamParams {
  double z_hit = 0.7;
  double z_short = 0.1;
  double z_max = 0.1;
  double z_rand = 0.1;
  double sigma_hit_m = 0.03;
  double lambda_short_per_m = 2.0;
};

// Everything that describes one sensor, independent of where it is mounted.
struct SensorSpec {
  std::string name;
  ForwardModelKind model = ForwardModelKind::kPaper3d;
  double r_min_m = 0.0;
  // Beam length N * cell_size. For sensors with r_max = inf (stereo) this is only the modelled
  // beam length (see range_unbounded).
  double r_max_m = 7.5;
  double fov_h_rad = 0.0;               // full horizontal field of view
  double fov_v_rad = 0.0;               // full vertical field of view
  int cols = 1;                         // beams across (azimuth)
  int rows = 1;                         // beams down (elevation)
  Polynomial2 q_mu{0.0, 1.0, 0.0};      // expected reading for a surface at range r
  Polynomial2 q_sigma{0.0, 0.0, 0.01};  // reading standard deviation at range r
  double epsilon = 0.01;                // paper's eps (total mass of the outlier part)
  double delta = 3.0;                   // paper's Delta: ROI half-width in sigmas
  ClassicBeamParams classic;            // used when model == kClassicBeam
  // True when the sensor has no maximum range (stereo, paper Table I: r_max = inf). Such a
  // sensor never reports "no return": a point is the outcome `beyond` only when the caller
  // marks it so, or when its range exceeds r_limit (a real return from beyond the modelled
  // beam, which says every modelled cell is free).
  bool range_unbounded = false;
};

// Empty string if the spec can be used to build a forward model / beam grid, otherwise the
// reason: r_min >= 0, r_max > r_min, 0 < epsilon < 1, delta > 0, 0 < fov_h <= 2 pi,
// 0 < fov_v < pi, cols, rows >= 1, classic weights >= 0 with a positive sum, sigma_hit > 0.
[[nodiscard]] std::string ValidateSensorSpec(const SensorSpec& spec);

// Paper presets: "sr3000" (SwissRanger SR-3000) and "stoc" (Videre STOC stereo camera),
// with exactly the coefficients of Tables I and II. std::nullopt for an unknown name.
// STOC has r_max = inf in the paper; its preset uses a beam length r_max_m = 5.0 m and sets
// range_unbounded. Both use the paper's 3D model (Algorithm III.1), epsilon = 0.01, Delta = 3.
[[nodiscard]] std::optional<SensorSpec> SensorPreset(const std::string& name);
[[nodiscard]] std::vector<std::string> SensorPresetNames();

}  // namespace fusion
