// Sensor presets (paper Tables I and II) and spec validation.
#include "fusion/core/sensor.h"

#include <algorithm>
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

// A Kinect v1 (structured light, 640 x 480) with the TUM fr2 intrinsics (the data set's
// published calibration). The forward model: fusion-calibrate on TUM fr2/pioneer_slam2, each
// frame against its own floor (--plane-per-cloud: the ground-truth poses tilt the floor by 1-3
// degrees from frame to frame) for the bias, and the noise from residuals against local planes
// in 5 cm cells (--local-patch 0.05: what the floor's warp and the poses add is not the
// sensor's; docs/sensors.md, "Calibrating a sensor"); fitted over 1.17..3.06 m, sigma 3 mm at
// 1.25 m, 5.7 mm at 2 m, 11 mm at 3 m. Range 0.5 m (the nearest the projector resolves) to 6 m.
SensorSpec KinectV1() {
  SensorSpec s;
  s.name = "kinect_v1";
  s.model = ForwardModelKind::kPaper3d;
  s.r_min_m = 0.5;
  s.r_max_m = 6.0;
  SetPinhole({520.9, 521.0, 325.1, 249.7, 640, 480, 1}, &s);
  s.q_mu = {0.001521562, 1.001785, -0.007137145};
  s.q_sigma = {0.001034751, 0.000242654, 0.001046363};
  s.epsilon = 0.0005329127;
  return s;
}

// A 3D laser scanner: a 2D scanner on a tilting unit, as OctoMap's sample scan was taken (497
// sweeps of 1-degree steps across, ~0.08 degrees of tilt apart): 184 x 41 degrees (azimuth
// -92..92, elevation -8..33: the scan's -91..91 x -7..32 and a margin), 0.5-degree beams (half
// the azimuth step; several sweeps a row), 0.3..30 m. Range noise constant: 15 mm, the
// systematic error a SICK LMS 200 class scanner's data sheet gives (its statistical error,
// 5 mm 1 sigma, is smaller; the tilting unit's pose error adds to both at range).
SensorSpec Laser3d() {
  SensorSpec s;
  s.name = "laser_3d";
  s.model = ForwardModelKind::kPaper3d;
  s.r_min_m = 0.3;
  s.r_max_m = 30.0;
  SetAngularLimits(DegToRad(-92.0), DegToRad(92.0), DegToRad(-8.0), DegToRad(33.0), &s);
  // Half a degree across (the sample scanner steps 1 degree); up 0.02 degrees, a quarter of its
  // sweeps' ~0.08-degree tilt step: a beam that holds two sweeps of a floor seen at a grazing
  // angle holds readings metres apart, and its first-hit distribution splits between them
  // (BENCHMARKS.md).
  s.cols = 368;
  s.rows = 2048;
  s.q_mu = {0.0, 1.0, 0.0};
  s.q_sigma = {0.0, 0.0, 0.015};
  s.epsilon = 0.02;
  // A surface every metre is what a camera indoors expects; a laser sees tens of metres, and
  // with a 1 m prior a single return at 20 m is explained as an outlier of a nearer surface
  // (it neither marks nor clears: FarReturnTest, BENCHMARKS.md).
  s.beam_prior_length_m = 5.0;
  return s;
}

bool Finite(double v) { return std::isfinite(v); }

std::string ValidatePinhole(const SensorSpec& spec) {
  const PinholeIntrinsics& k = *spec.pinhole;
  if (!(k.fx_px > 0.0) || !(k.fy_px > 0.0) || !Finite(k.fx_px) || !Finite(k.fy_px)) {
    return "pinhole focal lengths must be finite and > 0";
  }
  if (!Finite(k.cx_px) || !Finite(k.cy_px)) return "pinhole principal point must be finite";
  if (k.width_px < 1 || k.height_px < 1 || k.stride < 1) {
    return "pinhole image must be at least 1 x 1 pixels with a stride >= 1";
  }
  if (spec.cols != (k.width_px + k.stride - 1) / k.stride ||
      spec.rows != (k.height_px + k.stride - 1) / k.stride) {
    return "cols and rows must be the pinhole's strided image size";
  }
  return {};
}

}  // namespace

void SetPinhole(const PinholeIntrinsics& k, SensorSpec* spec) {
  spec->pinhole = k;
  const int stride = std::max(1, k.stride);
  spec->cols = (k.width_px + stride - 1) / stride;
  spec->rows = (k.height_px + stride - 1) / stride;
  // The image's edges as angles (pixel u covers [u - 0.5, u + 0.5)); the vertical ones at
  // azimuth 0, where elevation and the image's y / z agree.
  const double left = std::atan((-0.5 - k.cx_px) / k.fx_px);
  const double right = std::atan((k.width_px - 0.5 - k.cx_px) / k.fx_px);
  const double top = std::atan((k.cy_px + 0.5) / k.fy_px);
  const double bottom = std::atan((k.cy_px - k.height_px + 0.5) / k.fy_px);
  spec->fov_h_rad = right - left;
  spec->fov_v_rad = top - bottom;
  spec->azimuth_centre_rad = 0.5 * (left + right);
  spec->elevation_centre_rad = 0.5 * (top + bottom);
}

void SetAngularLimits(double azimuth_min_rad, double azimuth_max_rad, double elevation_min_rad,
                      double elevation_max_rad, SensorSpec* spec) {
  spec->pinhole.reset();
  spec->fov_h_rad = azimuth_max_rad - azimuth_min_rad;
  spec->fov_v_rad = elevation_max_rad - elevation_min_rad;
  spec->azimuth_centre_rad = 0.5 * (azimuth_min_rad + azimuth_max_rad);
  spec->elevation_centre_rad = 0.5 * (elevation_min_rad + elevation_max_rad);
}

namespace {

// The widest a grown field of view may reach from the optical axis (tangent tables need less
// than 90 degrees), and the most beams an axis grows by on each side (half its own).
constexpr double kMaxGrownRad = 85.0 * kPi / 180.0;

// Beams of `width_rad` to add on each side of [lo_rad, hi_rad] (of `beams` beams) for
// `margin_rad` more.
int AngularMargin(double lo_rad, double hi_rad, double width_rad, int beams, double margin_rad) {
  const double room = kMaxGrownRad - std::max(std::abs(lo_rad), std::abs(hi_rad));
  if (!(room > 0.0)) return 0;
  const int wanted = static_cast<int>(std::ceil(std::min(margin_rad, room) / width_rad));
  const int fits = static_cast<int>(std::floor(room / width_rad));
  return std::min({wanted, fits, beams / 2});
}

// Pixels to add beyond an image edge whose tangent (pointing outwards) is `edge_tan`.
double PixelMargin(double edge_tan, double focal_px, double margin_rad) {
  const double grown = std::min(std::atan(edge_tan) + margin_rad, kMaxGrownRad);
  return std::max(0.0, (std::tan(grown) - edge_tan) * focal_px);
}

// Strides of pixels to add on both sides of an image axis (edges at -0.5 and size - 0.5).
int PinholeMargin(double centre_px, int size_px, double focal_px, int stride, double margin_rad) {
  const double low = PixelMargin((centre_px + 0.5) / focal_px, focal_px, margin_rad);
  const double high = PixelMargin((size_px - 0.5 - centre_px) / focal_px, focal_px, margin_rad);
  const int beams = (size_px + stride - 1) / stride;
  return std::min(static_cast<int>(std::ceil(std::max(low, high) / stride)), beams / 2);
}

}  // namespace

SensorSpec WidenedFieldOfView(const SensorSpec& spec, double margin_rad, BeamMargin* margin) {
  *margin = BeamMargin{};
  SensorSpec out = spec;
  if (!(margin_rad > 0.0) || !std::isfinite(margin_rad)) return out;
  if (spec.pinhole) {
    PinholeIntrinsics k = *spec.pinhole;
    const int s = std::max(1, k.stride);
    margin->cols = PinholeMargin(k.cx_px, k.width_px, k.fx_px, s, margin_rad);
    margin->rows = PinholeMargin(k.cy_px, k.height_px, k.fy_px, s, margin_rad);
    k.width_px += 2 * margin->cols * s;
    k.cx_px += margin->cols * s;
    k.height_px += 2 * margin->rows * s;
    k.cy_px += margin->rows * s;
    SetPinhole(k, &out);
    return out;
  }
  const double width_h = spec.fov_h_rad / spec.cols, width_v = spec.fov_v_rad / spec.rows;
  margin->cols =
      AngularMargin(spec.azimuth_centre_rad - 0.5 * spec.fov_h_rad,
                    spec.azimuth_centre_rad + 0.5 * spec.fov_h_rad, width_h, spec.cols, margin_rad);
  margin->rows = AngularMargin(spec.elevation_centre_rad - 0.5 * spec.fov_v_rad,
                               spec.elevation_centre_rad + 0.5 * spec.fov_v_rad, width_v,
                               spec.rows, margin_rad);
  if (margin->cols > 0) {
    out.cols += 2 * margin->cols;
    out.fov_h_rad = width_h * out.cols;
  }
  if (margin->rows > 0) {
    out.rows += 2 * margin->rows;
    out.fov_v_rad = width_v * out.rows;
  }
  return out;
}

std::optional<SensorSpec> SensorPreset(const std::string& name) {
  if (name == "sr3000") return Sr3000();
  if (name == "stoc") return Stoc();
  if (name == "kinect_v1") return KinectV1();
  if (name == "laser_3d") return Laser3d();
  return std::nullopt;
}

std::vector<std::string> SensorPresetNames() { return {"sr3000", "stoc", "kinect_v1", "laser_3d"}; }

std::string ValidateSensorSpec(const SensorSpec& spec) {
  if (!Finite(spec.r_min_m) || spec.r_min_m < 0.0) return "r_min_m must be finite and >= 0";
  if (!Finite(spec.r_max_m) || spec.r_max_m <= spec.r_min_m) {
    return "r_max_m must be finite and > r_min_m (use the beam length for unbounded sensors)";
  }
  if (!(spec.epsilon > 0.0 && spec.epsilon < 1.0)) return "epsilon must be in (0, 1)";
  if (!(spec.delta > 0.0) || !Finite(spec.delta)) return "delta must be finite and > 0";
  if (!(spec.beam_prior_length_m >= 0.0 && spec.beam_prior_length_m <= 1000.0)) {
    return "beam_prior_length_m must be 0 (the map's) or lie in (0, 1000] m";
  }
  // A pinhole's field of view follows from its intrinsics: those are what to name.
  if (spec.pinhole) {
    if (std::string e = ValidatePinhole(spec); !e.empty()) return e;
  }
  if (!(spec.fov_h_rad > 0.0 && spec.fov_h_rad <= 2.0 * kPi))
    return "fov_h_rad must be in (0, 2 pi]";
  if (!(spec.fov_v_rad > 0.0 && spec.fov_v_rad < kPi)) return "fov_v_rad must be in (0, pi)";
  if (spec.cols < 1 || spec.rows < 1) return "cols and rows must be >= 1";
  // A little slack for limits given in degrees (180 / 90 converted to radians).
  constexpr double kSlack = 1e-9;
  if (!Finite(spec.azimuth_centre_rad) ||
      std::abs(spec.azimuth_centre_rad) + 0.5 * spec.fov_h_rad > kPi + kSlack) {
    return "azimuth_centre_rad and fov_h_rad must keep the field of view within azimuth "
           "-180..180 degrees";
  }
  if (!Finite(spec.elevation_centre_rad) ||
      !(std::abs(spec.elevation_centre_rad) + 0.5 * spec.fov_v_rad < 0.5 * kPi)) {
    return "elevation_centre_rad and fov_v_rad must keep the field of view within elevation "
           "-90..90 degrees (exclusive)";
  }
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
