// Sensor presets (paper Tables I and II) and spec validation.
#include "fusion/core/sensor.h"

#include <cmath>

namespace fusion {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double DegToRad(double deg) { return deg * kPi / 180.0; }

SensorSpec Sr3000() {
  SensorSpec s;
  s.name = "sr3000";
  s.model = ForwardModelKind::kPaper3d;
  s.r_min_m = 0.600;
  s.r_max_m = 7.500;
  s.fov_h_rad = DegToRad(47.0);
  s.fov_v_rad = DegToRad(39.0);
  s.cols = 176;
  s.rows = 144;
  s.q_mu = Polynomial2::FromMillimetres(0.0, 1.0, 0.0);
  s.q_sigma = Polynomial2::FromMillimetres(-0.243897e-6, 0.486625e-2, -0.7691149);
  s.range_unbounded = false;
  return s;
}

SensorSpec Stoc() {
  SensorSpec s;
  s.name = "stoc";
  s.model = ForwardModelKind::kPaper3d;
  s.r_min_m = 0.686;
  s.r_max_m = 5.0;  // paper: inf; 5 m is the modelled beam length (range_unbounded)
  s.fov_h_rad = DegToRad(65.5);
  s.fov_v_rad = DegToRad(51.5);
  s.cols = 640;
  s.rows = 480;
  s.q_mu = Polynomial2::FromMillimetres(0.0, 1.150204, -78.158607);
  s.q_sigma = Polynomial2::FromMillimetres(0.947909e-5, -0.178817e-1, 11.186380);
  s.range_unbounded = true;
  return s;
}

bool Finite(double v) { return std::isfinite(v); }

}  // namespace

std::optional<SensorSpec> SensorPreset(const std::string& name) {
  if (name == "sr3000") return Sr3000();
  if (name == "stoc") return Stoc();
  return std::nullopt;
}

std::vector<std::string> SensorPresetNames() { return {"sr3000", "stoc"}; }

std::string ValidateSensorSpec(const SensorSpec& spec) {
  if (!Finite(spec.r_min_m) || spec.r_min_m < 0.0) return "r_min_m must be finite and >= 0";
  if (!Finite(spec.r_max_m) || spec.r_max_m <= spec.r_min_m) {
    return "r_max_m must be finite and > r_min_m (use the beam length for unbounded sensors)";
  }
  if (!(spec.epsilon > 0.0 && spec.epsilon < 1.0)) return "epsilon must be in (0, 1)";
  if (!(spec.delta > 0.0) || !Finite(spec.delta)) return "delta must be finite and > 0";
  if (!(spec.fov_h_rad > 0.0 && spec.fov_h_rad <= 2.0 * kPi))
    return "fov_h_rad must be in (0, 2 pi]";
  if (!(spec.fov_v_rad > 0.0 && spec.fov_v_rad < kPi)) return "fov_v_rad must be in (0, pi)";
  if (spec.cols < 1 || spec.rows < 1) return "cols and rows must be >= 1";
  for (double c : {spec.q_mu.a0, spec.q_mu.a1, spec.q_mu.a2, spec.q_sigma.a0, spec.q_sigma.a1,
                   spec.q_sigma.a2}) {
    if (!Finite(c)) return "polynomial coefficients must be finite";
  }
  if (spec.model == ForwardModelKind::kClassicBeam) {
    const ClassicBeamParams& c = spec.classic;
    for (double w : {c.z_hit, c.z_short, c.z_max, c.z_rand}) {
      if (!Finite(w) || w < 0.0) return "classic mixture weights must be finite and >= 0";
    }
    if (!(c.z_hit + c.z_short + c.z_max + c.z_rand > 0.0)) {
      return "classic mixture weights must have a positive sum";
    }
    if (!(c.sigma_hit_m > 0.0) || !Finite(c.sigma_hit_m)) return "sigma_hit_m must be > 0";
    if (!(c.lambda_short_per_m > 0.0) || !Finite(c.lambda_short_per_m)) {
      return "lambda_short_per_m must be > 0";
    }
  }
  return {};
}

}  // namespace fusion
