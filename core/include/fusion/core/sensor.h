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

// A camera's intrinsics in pixels (OpenCV's convention, as a ROS CameraInfo's K: pixel (u, v)
// is centred at u = fx x / z + cx, v = fy y / z + cy in the optical frame and covers
// [u - 0.5, u + 0.5) x [v - 0.5, v + 0.5)), and the pixels per beam along each axis.
struct PinholeIntrinsics {
  double fx_px = 0.0;
  double fy_px = 0.0;
  double cx_px = 0.0;
  double cy_px = 0.0;
  int width_px = 0;
  int height_px = 0;
  int stride = 1;  // beam (c, r) holds pixels [c s, (c + 1) s) x [r s, (r + 1) s), clipped
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
  // Direction of the field of view's centre: azimuth (towards +x) and elevation (towards -y);
  // 0, 0 (the default) is a field of view symmetric about the optical axis. SetAngularLimits
  // sets these and the widths from a scanner's limits.
  double azimuth_centre_rad = 0.0;
  double elevation_centre_rad = 0.0;
  int cols = 1;                         // beams across (azimuth)
  int rows = 1;                         // beams down (elevation)
  // Set: a camera, one beam per (strided) pixel, instead of beams uniform in angle. SetPinhole
  // sets it together with cols, rows and the angular extent (fov_*, *_centre_rad) it implies.
  std::optional<PinholeIntrinsics> pinhole;
  Polynomial2 q_mu{0.0, 1.0, 0.0};      // expected reading for a surface at range r
  Polynomial2 q_sigma{0.0, 0.0, 0.01};  // reading standard deviation at range r
  double epsilon = 0.01;                // paper's eps (total mass of the outlier part)
  double delta = 3.0;                   // paper's Delta: ROI half-width in sigmas
  // The beam prior of this sensor's beams (docs/mapping.md, "The beam prior"): a run of this
  // many metres holds a surface with probability 0.5 before any reading. 0 (the default): the
  // map's (WorldMapOptions::beam_prior_length_m). A laser that sees far in open space wants a
  // longer prior than a camera (laser_3d: 5 m); otherwise in (0, 1000].
  double beam_prior_length_m = 0.0;
  ClassicBeamParams classic;            // used when model == kClassicBeam
  // True when the sensor has no maximum range (stereo, paper Table I: r_max = inf). Such a
  // sensor never reports "no return": a point is the outcome `beyond` only when the caller
  // marks it so, or when its range exceeds r_limit (a real return from beyond the modelled
  // beam, which says every modelled cell is free).
  bool range_unbounded = false;
};

// Makes `spec` a pinhole sensor with intrinsics `k`: sets pinhole, cols = ceil(width / stride),
// rows = ceil(height / stride) and the image's angular extent (fov_h_rad, fov_v_rad and the
// centres; the vertical one measured at azimuth 0).
void SetPinhole(const PinholeIntrinsics& k, SensorSpec* spec);
// An angular field of view between the given azimuths (right of the optical axis positive) and
// elevations (up positive), radians: sets fov_*_rad and *_centre_rad, drops any pinhole.
void SetAngularLimits(double azimuth_min_rad, double azimuth_max_rad, double elevation_min_rad,
                      double elevation_max_rad, SensorSpec* spec);

// `spec` with its field of view grown by at least `margin_rad` on every side, in whole beams of
// the same size (pinhole: whole strides of pixels beyond the image's edges), so that beam
// (col, row) of `spec` is beam (col + margin.cols, row + margin.rows) of the result. An axis
// grows by at most half its own beams a side, and an angular one no further than 85 degrees
// from the optical axis (not at all if it reaches that already). A strided image's clipped last
// column or row (ceil(width / stride) beams) is whole in the result: it holds what it held,
// and a little more. A sensor period's beam grid (SensorPeriods) is grown so, to keep the
// readings of frames taken near, not at, its pose.
struct BeamMargin {
  int cols = 0;  // beams added left and right
  int rows = 0;  // beams added above and below
};
[[nodiscard]] SensorSpec WidenedFieldOfView(const SensorSpec& spec, double margin_rad,
                                            BeamMargin* margin);

// Empty string if the spec can be used to build a forward model / beam grid, otherwise the
// reason: r_min >= 0, r_max > r_min, 0 < epsilon < 1, delta > 0, beam_prior_length_m 0 or in
// (0, 1000], 0 < fov_h <= 2 pi,
// 0 < fov_v < pi, the field of view within azimuth [-pi, pi] and elevation (-pi/2, pi/2),
// cols, rows >= 1, a pinhole's focal lengths > 0, image >= 1 x 1, stride >= 1 and cols / rows
// its strided image's, classic weights >= 0 with a positive sum, sigma_hit > 0.
[[nodiscard]] std::string ValidateSensorSpec(const SensorSpec& spec);

// Presets. The paper's "sr3000" (SwissRanger SR-3000) and "stoc" (Videre STOC stereo camera),
// with exactly the coefficients of Tables I and II; STOC has r_max = inf in the paper, its
// preset uses a beam length r_max_m = 5.0 m and sets range_unbounded. Both use the paper's 3D
// model (Algorithm III.1), epsilon = 0.01, Delta = 3. "kinect_v1": a 640 x 480 pinhole depth
// camera (the TUM fr2 intrinsics) with the forward model fitted by fusion-calibrate on the
// TUM fr2/pioneer_slam2 recording; "laser_3d": a 3D laser scanner with constant range noise
// and OctoMap's sample scan's field of view (docs/sensors.md names the sources).
// std::nullopt for an unknown name.
[[nodiscard]] std::optional<SensorSpec> SensorPreset(const std::string& name);
[[nodiscard]] std::vector<std::string> SensorPresetNames();

}  // namespace fusion
