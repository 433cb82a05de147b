// Forward models calibrated from recorded data (docs/sensors.md, "Calibrating a sensor").
//
// A sample pairs the true range t of a target along a reading's beam with the reading r. The
// model is the one Algorithm III.1 is built from: with probability 1 - eps the reading is
// N(q_mu(t), q_sigma(t)^2), with probability eps it is an outlier, uniform over the readings'
// span [outlier_lo, outlier_hi]. CalibrateForwardModel estimates q_mu, q_sigma (polynomials in
// t, Polynomial2 in metres, the bias q_mu(t) - t and q_sigma of degree 0..2), eps and the
// range the data supports by maximum
// likelihood: EM whose M-step is a weighted least-squares fit of q_mu and Fisher-scoring steps
// on the log-likelihood for q_sigma, started from a median / MAD fit per range bin so gross
// outliers do not steer it.
//
// Helpers make samples from clouds: the true range along a point's direction is where the ray
// meets a reference plane of the world frame, given or found as the dominant plane.
//
// Errors: misuse (a degree outside 0..2, no bins, null pointers) throws std::invalid_argument;
// data that cannot be fitted (too few samples, no target, a degenerate range spread) is
// reported in the result's `error` (empty on success), which callers must look at.
#pragma once

#include <Eigen/Geometry>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#include "fusion/core/sensor.h"

namespace fusion {

struct RangeSample {
  double true_range_m = 0.0;  // t: range of the target along the reading's beam
  double reading_m = 0.0;     // r: the range the sensor reported (norm of the point)
};

struct CalibrationOptions {
  static constexpr double kInfinity = std::numeric_limits<double>::infinity();
  // Degree 0..2 of the bias q_mu(t) - t and of q_sigma (the paper's Table II: 2). For 1 and 2
  // that is q_mu's degree; 0 is a constant bias (q_mu = t + a0) and a constant sigma.
  int degree = 2;
  int bins = 12;  // range bins of the table and of the robust initialisation, >= 1
  // Samples whose true range lies outside [window_min_m, window_max_m] are not considered.
  double window_min_m = 0.0;
  double window_max_m = kInfinity;
  std::size_t min_samples = 200;     // fewer samples in the window: error
  std::size_t min_bin_samples = 20;  // a bin with fewer does not initialise the fit
  // Each degree needs this much spread of the true ranges (5th to 95th percentile): a board
  // at one distance cannot say how the bias curves.
  double min_spread_per_degree_m = 0.4;
  int max_iterations = 300;
  double tolerance = 1e-10;  // EM stops when the log-likelihood per sample gains less
};

// One range bin of the fit's table. Inliers: responsibility >= 0.5.
struct CalibrationBin {
  double begin_m = 0.0, end_m = 0.0, centre_m = 0.0;  // true-range interval
  std::size_t count = 0, inliers = 0, outliers = 0;
  double measured_bias_m = 0.0;  // mean(r - t) over the inliers (NaN without)
  // Std of r - q_mu(t) over the inliers (the fitted mean takes out the bias's slope inside
  // the bin; NaN with fewer than 2).
  double measured_sigma_m = 0.0;
  double fitted_bias_m = 0.0;   // q_mu(centre) - centre
  double fitted_sigma_m = 0.0;  // q_sigma(centre)
};

struct Calibration {
  std::string error;  // empty when the fit succeeded; otherwise why, and what to try
  int degree = 2;
  Polynomial2 q_mu{0.0, 1.0, 0.0};
  Polynomial2 q_sigma{0.0, 0.0, 0.01};
  double epsilon = 0.0;
  double r_min_m = 0.0, r_max_m = 0.0;            // true ranges of the inliers: where the fit holds
  double outlier_lo_m = 0.0, outlier_hi_m = 0.0;  // support of the outlier density
  double log_likelihood = 0.0;                    // of the considered samples at the fit, nats
  std::size_t samples = 0;                        // considered (inside the window)
  std::size_t inliers = 0;
  int iterations = 0;
  bool converged = false;
  std::vector<CalibrationBin> bins;
  // Per input sample, in input order: P(inlier | r, t) at the fit; NaN outside the window.
  std::vector<double> inlier_responsibility;
  [[nodiscard]] bool ok() const { return error.empty(); }
};

// The maximum-likelihood forward model of the samples (see the top of this file). Throws
// std::invalid_argument for options.degree outside 0..2 or options.bins < 1.
[[nodiscard]] Calibration CalibrateForwardModel(const std::vector<RangeSample>& samples,
                                                const CalibrationOptions& options = {});

// Mixture log-likelihood (nats) of the samples under q_mu, q_sigma, eps with outliers uniform
// over [outlier_lo_m, outlier_hi_m]; sigma is floored at 1 um.
[[nodiscard]] double CalibrationLogLikelihood(const std::vector<RangeSample>& samples,
                                              const Polynomial2& q_mu, const Polynomial2& q_sigma,
                                              double epsilon, double outlier_lo_m,
                                              double outlier_hi_m);

// A plane a x + b y + c z + d = 0 as (a, b, c, d), (a, b, c) != 0. The helpers normalise it.
using PlaneCoefficients = Eigen::Vector4d;

// (a, b, c) scaled to unit length and the sign fixed so its largest component is positive
// (so a plane prints the same however it was found). Throws std::invalid_argument when
// (a, b, c) is zero or a coefficient is not finite.
[[nodiscard]] PlaneCoefficients NormalizedPlane(const PlaneCoefficients& plane);

struct PlaneSampleOptions {
  // Rays whose |cos(angle to the plane's normal)| is below this are nearly parallel to the
  // plane (the true range is then ill-conditioned): skipped.
  double min_incidence_cos = 0.1;
  // A point is a sample only if |r - t| <= max_residual_m + max_residual_fraction * t, so that
  // points on other surfaces (walls above a floor) are not taken as readings of the plane.
  // Default: no gate.
  double max_residual_m = CalibrationOptions::kInfinity;
  double max_residual_fraction = 0.0;
};

struct PlaneSampleStats {
  std::size_t points = 0;    // looked at
  std::size_t missing = 0;   // NaN, inf or at the origin
  std::size_t parallel = 0;  // ray nearly parallel to the plane
  std::size_t behind = 0;    // the plane is behind the sensor along the ray
  std::size_t gated = 0;     // residual beyond the gate
  std::size_t samples = 0;   // appended
};

// Appends one sample per usable point: points_xyz holds 3 floats per point in the sensor frame
// (metres), T_world_sensor is the sensor's pose, plane_world the target in the world frame.
// The true range is the distance from the sensor origin to where the point's ray meets the
// plane; the reading is the point's norm. Throws std::invalid_argument for null pointers
// (with point_count > 0) or an invalid plane.
PlaneSampleStats AppendPlaneSamples(const float* points_xyz, std::size_t point_count,
                                    const Eigen::Isometry3d& T_world_sensor,
                                    const PlaneCoefficients& plane_world,
                                    const PlaneSampleOptions& options,
                                    std::vector<RangeSample>* samples);

// The sensor's own noise, apart from the reference's error. Against one reference plane the
// residuals hold the reference's error too (a pose that tilts the floor, a plane that is not
// flat): it varies slowly across the target, the sensor's noise from point to point. Local
// samples take each point's true range from a plane fitted to its own neighbourhood: the
// points of the same cloud in the same patch_m x patch_m cell of the reference plane (total
// least squares, refitted without the points beyond 3.5 robust sigmas). Their residuals
// r - t_local, scaled by sqrt(m / (m - 3)) for the plane's three fitted parameters (m points),
// keep what varies within a cell and lose the bias, which moves the local plane with it: fit
// the noise (q_sigma, eps) from them and the bias from the reference (WithLocalNoise).
struct LocalPlaneOptions {
  double patch_m = 0.1;         // cell edge on the reference plane, > 0
  std::size_t min_points = 12;  // a cell with fewer points (after the refit) gives no samples
};

struct LocalSampleStats {
  PlaneSampleStats plane;       // the points' selection, as AppendPlaneSamples; samples: appended
  std::size_t cells = 0;        // cells that gave samples
  std::size_t sparse = 0;       // points in cells too sparse or degenerate for a plane
};

// Appends one sample per point on the reference plane (selected as AppendPlaneSamples does) in
// a cell with enough points: true_range_m the reference plane's t, reading_m = t + the scaled
// residual against the local plane. Throws std::invalid_argument as AppendPlaneSamples, and for
// patch_m <= 0 or min_points < 4.
LocalSampleStats AppendLocalPlaneSamples(const float* points_xyz, std::size_t point_count,
                                         const Eigen::Isometry3d& T_world_sensor,
                                         const PlaneCoefficients& plane_world,
                                         const PlaneSampleOptions& options,
                                         const LocalPlaneOptions& local,
                                         std::vector<RangeSample>* samples);

// The model with the bias from `reference` (q_mu, the range it holds, samples, inliers,
// log-likelihood, responsibilities: samples against the reference plane) and the noise from
// `local` (q_sigma, eps: samples of AppendLocalPlaneSamples); each bin's sigmas are the local
// fit's (measured: the local bin holding the bin's centre). Both must be ok().
[[nodiscard]] Calibration WithLocalNoise(const Calibration& reference, const Calibration& local);

// Appends the world-frame position of every finite point within near_m of the sensor (range
// in the sensor frame) to *points_world: the candidates of FitDominantPlane.
void AppendNearPointsWorld(const float* points_xyz, std::size_t point_count,
                           const Eigen::Isometry3d& T_world_sensor, double near_m,
                           std::vector<Eigen::Vector3d>* points_world);

struct PlaneFitOptions {
  int iterations = 1000;                  // RANSAC hypotheses
  double inlier_distance_m = 0.02;        // a point within this of a plane supports it
  std::uint64_t seed = 1;                 // deterministic
  std::size_t min_points = 100;           // fewer candidates: "no target found"
  double min_inlier_fraction = 0.2;       // the dominant plane must hold this share of the points
  std::size_t max_scored_points = 20000;  // hypotheses are scored on a fixed subsample
};

struct PlaneFit {
  std::string error;                                        // empty on success
  PlaneCoefficients plane = PlaneCoefficients(0, 0, 1, 0);  // normalised (NormalizedPlane)
  std::size_t points = 0;                                   // candidates
  std::size_t inliers = 0;  // within inlier_distance_m of the refined plane
  double rms_m = 0.0;       // of the inliers' distances
  [[nodiscard]] bool ok() const { return error.empty(); }
};

// The plane holding most points (world frame, metres): RANSAC over point triples, then a
// total-least-squares refinement on the inliers (twice). Deterministic for a seed.
[[nodiscard]] PlaneFit FitDominantPlane(const std::vector<Eigen::Vector3d>& points_world,
                                        const PlaneFitOptions& options = {});

}  // namespace fusion
