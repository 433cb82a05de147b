// Maximum-likelihood forward models from (true range, reading) samples; the plane helpers
// that make such samples from clouds. The model and the method: calibration.h.
#include "fusion/core/calibration.h"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <random>
#include <stdexcept>
#include <string>
#include <utility>

namespace fusion {
namespace {

constexpr double kSigmaFloorM = 1e-6;
constexpr double kMadToSigma = 1.482602218505602;  // sigma of a normal = 1.4826 MAD
constexpr double kInlierResponsibility = 0.5;
constexpr double kLog2Pi = 1.8378770664093453;

// Polynomial coefficients and bases of degree <= 2 on the stack (the hot loops run them per
// sample).
using Vec = Eigen::Matrix<double, Eigen::Dynamic, 1, 0, 3, 1>;
using Mat = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, 3, 3>;

std::string Metres(double v) {
  char text[32];
  std::snprintf(text, sizeof text, "%.3f", v);
  return text;
}

// Coefficients c0, c1, c2 (c_k multiplies t^k) of a polynomial of degree <= 2.
Polynomial2 FromCoefficients(const Vec& c) {
  double all[3] = {0.0, 0.0, 0.0};
  for (Eigen::Index k = 0; k < std::min<Eigen::Index>(c.size(), 3); ++k) all[k] = c.coeff(k);
  return Polynomial2{all[2], all[1], all[0]};
}

Vec ToCoefficients(const Polynomial2& p, int degree) {
  Vec c(degree + 1);
  const double all[3] = {p.a0, p.a1, p.a2};
  for (int k = 0; k <= degree; ++k) c[k] = all[k];
  return c;
}

Vec Basis(double t, int degree) {
  Vec phi(degree + 1);
  double power = 1.0;
  for (int k = 0; k <= degree; ++k, power *= t) phi[k] = power;
  return phi;
}

// Weighted least squares y ~ poly(x) of the given degree; *ok = false when the normal
// equations are singular (too few distinct x).
Polynomial2 WeightedPolyFit(const std::vector<double>& x, const std::vector<double>& y,
                            const std::vector<double>& w, int degree, bool* ok) {
  const int m = degree + 1;
  Mat normal = Mat::Zero(m, m);
  Vec rhs = Vec::Zero(m);
  for (std::size_t i = 0; i < x.size(); ++i) {
    if (!(w[i] > 0.0)) continue;
    const Vec phi = Basis(x[i], degree);
    normal.noalias() += w[i] * phi * phi.transpose();
    rhs.noalias() += w[i] * y[i] * phi;
  }
  const Eigen::LDLT<Mat> ldlt(normal);
  *ok = ldlt.info() == Eigen::Success && ldlt.isPositive() &&
        ldlt.vectorD().minCoeff() > 1e-12 * std::max(1.0, ldlt.vectorD().maxCoeff());
  if (!*ok) return Polynomial2{0.0, 0.0, 0.0};
  return FromCoefficients(ldlt.solve(rhs));
}

// q_mu(t) = t + bias(t), the bias a polynomial of the degree fitted to the readings r - t: the
// reading always grows with the range, so degree 0 is a constant bias, not a constant reading.
Polynomial2 BiasFit(const std::vector<double>& t, const std::vector<double>& r,
                    const std::vector<double>& w, int degree, bool* ok) {
  std::vector<double> bias(t.size());
  for (std::size_t i = 0; i < t.size(); ++i) bias[i] = r[i] - t[i];
  Polynomial2 mu = WeightedPolyFit(t, bias, w, degree, ok);
  mu.a1 += 1.0;
  return mu;
}

// Smallest value of a polynomial of degree <= 2 on [lo, hi] (ends and vertex).
double MinOnInterval(const Polynomial2& p, double lo, double hi) {
  double m = std::min(p(lo), p(hi));
  if (p.a2 != 0.0) {
    const double vertex = -p.a1 / (2.0 * p.a2);
    if (vertex > lo && vertex < hi) m = std::min(m, p(vertex));
  }
  return m;
}

double Median(std::vector<double> v) {
  const std::size_t mid = v.size() / 2;
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(mid), v.end());
  double m = v[mid];
  if (v.size() % 2 == 0) {
    m = 0.5 * (m + *std::max_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(mid)));
  }
  return m;
}

double Quantile(const std::vector<double>& sorted, double q) {
  const double pos = q * static_cast<double>(sorted.size() - 1);
  const auto i = static_cast<std::size_t>(pos);
  const double f = pos - static_cast<double>(i);
  return i + 1 < sorted.size() ? sorted[i] + f * (sorted[i + 1] - sorted[i]) : sorted[i];
}

// The considered samples, flat, with their bins.
struct Data {
  std::vector<double> t, r;
  std::vector<std::size_t> index;  // into the caller's samples
  std::vector<int> bin;
  double t_lo = 0.0, t_hi = 0.0, bin_width = 1.0;
  double log_uniform = 0.0;  // log of the outlier density
  int degree = 2;
};

struct Params {
  Polynomial2 mu, sigma;
  double eps = 0.01;
};

// The median / MAD start: per bin the median and spread of the residual about the current
// mean (first the identity), twice, so the bias's slope inside a bin does not widen the spread.
std::string RobustStart(const Data& d, const CalibrationOptions& o, Params* p) {
  p->mu = Polynomial2{0.0, 1.0, 0.0};
  const double floor_m = 1e-4;
  for (int round = 0; round < 2; ++round) {
    std::vector<std::vector<double>> res(static_cast<std::size_t>(o.bins));
    std::vector<std::vector<double>> ts(static_cast<std::size_t>(o.bins));
    for (std::size_t i = 0; i < d.t.size(); ++i) {
      const auto b = static_cast<std::size_t>(d.bin[i]);
      res[b].push_back(d.r[i] - p->mu(d.t[i]));
      ts[b].push_back(d.t[i]);
    }
    std::vector<double> x, y_mu, y_sigma, w;
    for (std::size_t b = 0; b < res.size(); ++b) {
      if (res[b].size() < o.min_bin_samples) continue;
      const double t_b = Median(ts[b]);
      const double m_b = Median(res[b]);
      std::vector<double> dev(res[b].size());
      for (std::size_t k = 0; k < dev.size(); ++k) dev[k] = std::abs(res[b][k] - m_b);
      x.push_back(t_b);
      y_mu.push_back(p->mu(t_b) + m_b);  // a reading: BiasFit takes t off
      y_sigma.push_back(std::max(floor_m, kMadToSigma * Median(dev)));
      w.push_back(static_cast<double>(res[b].size()));
    }
    if (x.size() < static_cast<std::size_t>(d.degree + 1)) {
      return "degenerate range spread: only " + std::to_string(x.size()) + " of " +
             std::to_string(o.bins) + " range bins hold " + std::to_string(o.min_bin_samples) +
             " samples or more, a degree-" + std::to_string(d.degree) + " fit needs " +
             std::to_string(d.degree + 1) +
             "; record the target at more distances or use a lower --degree";
    }
    bool ok = false;
    const Polynomial2 mu = BiasFit(x, y_mu, w, d.degree, &ok);
    if (!ok) return "degenerate range spread: the range bins do not determine the mean";
    p->mu = mu;
    Polynomial2 sigma = WeightedPolyFit(x, y_sigma, w, d.degree, &ok);
    if (!ok || MinOnInterval(sigma, d.t_lo, d.t_hi) <= floor_m) {
      double sum = 0.0, weight = 0.0;  // a constant start is still a start
      for (std::size_t k = 0; k < x.size(); ++k) sum += w[k] * y_sigma[k], weight += w[k];
      sigma = Polynomial2{0.0, 0.0, sum / weight};
    }
    p->sigma = sigma;
  }
  std::size_t far = 0;
  for (std::size_t i = 0; i < d.t.size(); ++i) {
    if (std::abs(d.r[i] - p->mu(d.t[i])) > 3.0 * p->sigma(d.t[i])) ++far;
  }
  p->eps = std::clamp(static_cast<double>(far) / static_cast<double>(d.t.size()), 1e-3, 0.5);
  return {};
}

double LogNormal(double r, double mu, double sigma) {
  const double z = (r - mu) / sigma;
  return -0.5 * (kLog2Pi + z * z) - std::log(sigma);
}

// E-step: responsibilities into *w; returns the log-likelihood.
double Expect(const Data& d, const Params& p, std::vector<double>* w) {
  const double log_in = std::log1p(-p.eps);
  const double log_out = std::log(p.eps) + d.log_uniform;
  double ll = 0.0;
  for (std::size_t i = 0; i < d.t.size(); ++i) {
    const double s = std::max(kSigmaFloorM, p.sigma(d.t[i]));
    const double a = log_in + LogNormal(d.r[i], p.mu(d.t[i]), s);
    const double hi = std::max(a, log_out);
    const double total = hi + std::log(std::exp(a - hi) + std::exp(log_out - hi));
    (*w)[i] = std::exp(a - total);
    ll += total;
  }
  return ll;
}

// The sigma part of the EM objective: sum w (-log s - e^2 / 2 s^2); -inf if s <= 0 somewhere.
double SigmaObjective(const Data& d, const std::vector<double>& w, const Polynomial2& mu,
                      const Polynomial2& sigma) {
  if (MinOnInterval(sigma, d.t_lo, d.t_hi) <= kSigmaFloorM) {
    return -std::numeric_limits<double>::infinity();
  }
  double q = 0.0;
  for (std::size_t i = 0; i < d.t.size(); ++i) {
    const double s = sigma(d.t[i]);
    const double e = d.r[i] - mu(d.t[i]);
    q += w[i] * (-std::log(s) - e * e / (2.0 * s * s));
  }
  return q;
}

// Fisher-scoring steps on the sigma polynomial (the expected Hessian is negative definite, so
// each step goes uphill), halved until the objective improves and sigma stays positive.
Polynomial2 FitSigma(const Data& d, const std::vector<double>& w, const Polynomial2& mu,
                     Polynomial2 sigma, int steps) {
  const int m = d.degree + 1;
  double q = SigmaObjective(d, w, mu, sigma);
  for (int step = 0; step < steps; ++step) {
    Mat info = Mat::Zero(m, m);
    Vec grad = Vec::Zero(m);
    for (std::size_t i = 0; i < d.t.size(); ++i) {
      const double s = sigma(d.t[i]);
      const double e = d.r[i] - mu(d.t[i]);
      const Vec phi = Basis(d.t[i], d.degree);
      grad.noalias() += w[i] * (e * e / (s * s * s) - 1.0 / s) * phi;
      info.noalias() += (2.0 * w[i] / (s * s)) * phi * phi.transpose();
    }
    const Vec delta = info.ldlt().solve(grad);
    if (!delta.allFinite()) break;
    const Vec c = ToCoefficients(sigma, d.degree);
    bool improved = false;
    for (double alpha = 1.0; alpha > 1e-6; alpha *= 0.5) {
      const Polynomial2 next = FromCoefficients(c + alpha * delta);
      const double q_next = SigmaObjective(d, w, mu, next);
      if (q_next >= q) {
        improved = q_next > q;
        sigma = next;
        q = q_next;
        break;
      }
    }
    if (!improved) break;
  }
  return sigma;
}

// M-step: eps, then q_mu by weighted least squares (weights w / sigma^2: exact given sigma),
// then q_sigma by scoring. Each part raises the expected log-likelihood, so EM climbs.
void Maximise(const Data& d, const std::vector<double>& w, Params* p) {
  double inlier_mass = 0.0;
  for (double wi : w) inlier_mass += wi;
  const auto n = static_cast<double>(d.t.size());
  p->eps = std::clamp(1.0 - inlier_mass / n, 1e-9, 0.999);
  std::vector<double> weight(d.t.size());
  for (std::size_t i = 0; i < d.t.size(); ++i) {
    const double s = std::max(kSigmaFloorM, p->sigma(d.t[i]));
    weight[i] = w[i] / (s * s);
  }
  bool ok = false;
  const Polynomial2 mu = BiasFit(d.t, d.r, weight, d.degree, &ok);
  if (ok) p->mu = mu;
  p->sigma = FitSigma(d, w, p->mu, p->sigma, 3);
}

std::vector<CalibrationBin> Table(const Data& d, const Params& p, const std::vector<double>& w,
                                  int bins) {
  std::vector<CalibrationBin> table(static_cast<std::size_t>(bins));
  std::vector<double> sum_bias(table.size()), sum_e(table.size()), sum_e2(table.size());
  for (std::size_t b = 0; b < table.size(); ++b) {
    CalibrationBin& bin = table[b];
    bin.begin_m = d.t_lo + static_cast<double>(b) * d.bin_width;
    bin.end_m = bin.begin_m + d.bin_width;
    bin.centre_m = 0.5 * (bin.begin_m + bin.end_m);
    bin.fitted_bias_m = p.mu(bin.centre_m) - bin.centre_m;
    bin.fitted_sigma_m = p.sigma(bin.centre_m);
  }
  for (std::size_t i = 0; i < d.t.size(); ++i) {
    const auto b = static_cast<std::size_t>(d.bin[i]);
    ++table[b].count;
    if (w[i] < kInlierResponsibility) {
      ++table[b].outliers;
      continue;
    }
    ++table[b].inliers;
    sum_bias[b] += d.r[i] - d.t[i];
    const double e = d.r[i] - p.mu(d.t[i]);
    sum_e[b] += e;
    sum_e2[b] += e * e;
  }
  const double nan = std::numeric_limits<double>::quiet_NaN();
  for (std::size_t b = 0; b < table.size(); ++b) {
    const auto k = static_cast<double>(table[b].inliers);
    table[b].measured_bias_m = k > 0 ? sum_bias[b] / k : nan;
    const double var = k > 1 ? (sum_e2[b] - sum_e[b] * sum_e[b] / k) / (k - 1.0) : nan;
    table[b].measured_sigma_m = std::sqrt(std::max(0.0, var));
    if (k < 2) table[b].measured_sigma_m = nan;
  }
  return table;
}

// The considered samples, or the reason there are not enough to fit.
std::string Select(const std::vector<RangeSample>& samples, const CalibrationOptions& o, Data* d) {
  for (std::size_t i = 0; i < samples.size(); ++i) {
    const double t = samples[i].true_range_m, r = samples[i].reading_m;
    if (!std::isfinite(t) || !std::isfinite(r) || t <= 0.0 || r <= 0.0) continue;
    if (t < o.window_min_m || t > o.window_max_m) continue;
    d->t.push_back(t);
    d->r.push_back(r);
    d->index.push_back(i);
  }
  const std::size_t needed = std::max<std::size_t>(o.min_samples, 3);
  if (d->t.size() < needed) {
    return "too few samples on the target: " + std::to_string(d->t.size()) +
           " with a true range in the window [" + Metres(o.window_min_m) + ", " +
           Metres(o.window_max_m) + "] m, at least " + std::to_string(needed) + " needed";
  }
  std::vector<double> sorted = d->t;
  std::sort(sorted.begin(), sorted.end());
  const double spread = Quantile(sorted, 0.95) - Quantile(sorted, 0.05);
  const double needed_m = o.min_spread_per_degree_m * d->degree;
  if (d->degree > 0 && spread < needed_m) {
    const int fits = static_cast<int>(std::floor(spread / o.min_spread_per_degree_m));
    return "degenerate range spread: the true ranges span only " + Metres(spread) + " m (" +
           Metres(Quantile(sorted, 0.05)) + " to " + Metres(Quantile(sorted, 0.95)) +
           " m, 5th to 95th percentile); a degree-" + std::to_string(d->degree) + " fit needs " +
           Metres(needed_m) + " m. Record the target at more distances, or " +
           "use a lower degree (--degree " + std::to_string(std::max(0, fits)) + ")";
  }
  d->t_lo = sorted.front();
  d->t_hi = sorted.back();
  d->bin_width = std::max(1e-9, (d->t_hi - d->t_lo) / o.bins);
  d->bin.resize(d->t.size());
  for (std::size_t i = 0; i < d->t.size(); ++i) {
    const int b = static_cast<int>((d->t[i] - d->t_lo) / d->bin_width);
    d->bin[i] = std::clamp(b, 0, o.bins - 1);
  }
  return {};
}

}  // namespace

double CalibrationLogLikelihood(const std::vector<RangeSample>& samples, const Polynomial2& q_mu,
                                const Polynomial2& q_sigma, double epsilon, double outlier_lo_m,
                                double outlier_hi_m) {
  const double log_u = -std::log(std::max(1e-3, outlier_hi_m - outlier_lo_m));
  double ll = 0.0;
  for (const RangeSample& s : samples) {
    const double sigma = std::max(kSigmaFloorM, q_sigma(s.true_range_m));
    const double a = std::log1p(-epsilon) + LogNormal(s.reading_m, q_mu(s.true_range_m), sigma);
    const bool inside = s.reading_m >= outlier_lo_m && s.reading_m <= outlier_hi_m;
    const double b = inside ? std::log(epsilon) + log_u : -std::numeric_limits<double>::infinity();
    const double hi = std::max(a, b);
    ll += hi + std::log(std::exp(a - hi) + std::exp(b - hi));
  }
  return ll;
}

Calibration CalibrateForwardModel(const std::vector<RangeSample>& samples,
                                  const CalibrationOptions& options) {
  if (options.degree < 0 || options.degree > 2) {
    throw std::invalid_argument("calibration degree must be 0, 1 or 2");
  }
  if (options.bins < 1) throw std::invalid_argument("calibration needs at least one range bin");
  Calibration result;
  result.degree = options.degree;
  result.inlier_responsibility.assign(samples.size(), std::numeric_limits<double>::quiet_NaN());
  Data d;
  d.degree = options.degree;
  result.error = Select(samples, options, &d);
  if (!result.ok()) return result;
  result.samples = d.t.size();
  const auto [r_lo, r_hi] = std::minmax_element(d.r.begin(), d.r.end());
  result.outlier_lo_m = *r_lo;
  result.outlier_hi_m = *r_hi;
  d.log_uniform = -std::log(std::max(1e-3, *r_hi - *r_lo));

  Params p;
  result.error = RobustStart(d, options, &p);
  if (!result.ok()) return result;
  std::vector<double> w(d.t.size());
  double ll = Expect(d, p, &w);
  const auto n = static_cast<double>(d.t.size());
  for (result.iterations = 0; result.iterations < options.max_iterations; ++result.iterations) {
    Maximise(d, w, &p);
    const double next = Expect(d, p, &w);
    const double gain = (next - ll) / n;
    ll = next;
    if (std::abs(gain) < options.tolerance) {
      result.converged = true;
      break;
    }
  }
  result.q_mu = p.mu;
  result.q_sigma = p.sigma;
  result.epsilon = p.eps;
  result.log_likelihood = ll;
  result.r_min_m = std::numeric_limits<double>::infinity();
  result.r_max_m = -std::numeric_limits<double>::infinity();
  for (std::size_t i = 0; i < d.t.size(); ++i) {
    result.inlier_responsibility[d.index[i]] = w[i];
    if (w[i] < kInlierResponsibility) continue;
    ++result.inliers;
    result.r_min_m = std::min(result.r_min_m, d.t[i]);
    result.r_max_m = std::max(result.r_max_m, d.t[i]);
  }
  if (result.inliers < options.min_samples) {
    result.error = "too few samples on the target: only " + std::to_string(result.inliers) +
                   " of " + std::to_string(result.samples) +
                   " samples fit a forward model (at least " + std::to_string(options.min_samples) +
                   " needed)";
    return result;
  }
  result.bins = Table(d, p, w, options.bins);
  return result;
}

PlaneCoefficients NormalizedPlane(const PlaneCoefficients& plane) {
  if (!plane.allFinite()) throw std::invalid_argument("plane coefficients must be finite");
  const double norm = plane.head<3>().norm();
  if (!(norm > 0.0)) throw std::invalid_argument("plane normal (a, b, c) must not be zero");
  PlaneCoefficients out = plane / norm;
  Eigen::Index largest = 0;
  out.head<3>().cwiseAbs().maxCoeff(&largest);
  if (out[largest] < 0.0) out = -out;
  return out;
}

namespace {

// One point against a plane: its reading r, unit ray direction in the world, the true range t
// where the ray meets the plane, or which of the stats' counters it goes to.
struct PlaneReading {
  std::size_t PlaneSampleStats::*counter = &PlaneSampleStats::samples;
  double t = 0.0, r = 0.0;
  Eigen::Vector3d ray_world = Eigen::Vector3d::Zero();
};

PlaneReading ReadPlane(const float* xyz, const Eigen::Isometry3d& T_world_sensor,
                       const PlaneCoefficients& plane, const PlaneSampleOptions& options) {
  PlaneReading out;
  const Eigen::Vector3d p(xyz[0], xyz[1], xyz[2]);
  out.r = p.norm();
  if (!std::isfinite(out.r) || out.r < 1e-9) {
    out.counter = &PlaneSampleStats::missing;
    return out;
  }
  out.ray_world = T_world_sensor.linear() * (p / out.r);
  const double cos_incidence = plane.head<3>().dot(out.ray_world);
  if (std::abs(cos_incidence) < options.min_incidence_cos) {
    out.counter = &PlaneSampleStats::parallel;
    return out;
  }
  const double origin_side = plane.head<3>().dot(T_world_sensor.translation()) + plane[3];
  out.t = -origin_side / cos_incidence;
  if (!(out.t > 0.0)) {
    out.counter = &PlaneSampleStats::behind;
  } else if (std::abs(out.r - out.t) >
             options.max_residual_m + options.max_residual_fraction * out.t) {
    out.counter = &PlaneSampleStats::gated;
  }
  return out;
}

void CheckSampleArguments(const float* points_xyz, std::size_t point_count, const void* samples,
                          const char* who) {
  if ((points_xyz == nullptr && point_count > 0) || samples == nullptr) {
    throw std::invalid_argument(std::string(who) + ": null points or samples");
  }
}

}  // namespace

PlaneSampleStats AppendPlaneSamples(const float* points_xyz, std::size_t point_count,
                                    const Eigen::Isometry3d& T_world_sensor,
                                    const PlaneCoefficients& plane_world,
                                    const PlaneSampleOptions& options,
                                    std::vector<RangeSample>* samples) {
  CheckSampleArguments(points_xyz, point_count, samples, "AppendPlaneSamples");
  const PlaneCoefficients plane = NormalizedPlane(plane_world);
  PlaneSampleStats stats;
  stats.points = point_count;
  for (std::size_t i = 0; i < point_count; ++i) {
    const PlaneReading hit = ReadPlane(points_xyz + 3 * i, T_world_sensor, plane, options);
    ++(stats.*hit.counter);
    if (hit.counter == &PlaneSampleStats::samples) samples->push_back({hit.t, hit.r});
  }
  return stats;
}

void AppendNearPointsWorld(const float* points_xyz, std::size_t point_count,
                           const Eigen::Isometry3d& T_world_sensor, double near_m,
                           std::vector<Eigen::Vector3d>* points_world) {
  if ((points_xyz == nullptr && point_count > 0) || points_world == nullptr) {
    throw std::invalid_argument("AppendNearPointsWorld: null points");
  }
  for (std::size_t i = 0; i < point_count; ++i) {
    const Eigen::Vector3d p(points_xyz[3 * i], points_xyz[3 * i + 1], points_xyz[3 * i + 2]);
    const double r = p.norm();
    if (!std::isfinite(r) || r < 1e-9 || r > near_m) continue;
    points_world->push_back(T_world_sensor * p);
  }
}

namespace {

// Total least squares through the points within `band` of the plane; false if fewer than 3.
bool RefinePlane(const std::vector<Eigen::Vector3d>& points, double band, PlaneCoefficients* pl) {
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  std::size_t k = 0;
  for (const auto& p : points) {
    if (std::abs(pl->head<3>().dot(p) + (*pl)[3]) > band) continue;
    mean += p;
    ++k;
  }
  if (k < 3) return false;
  mean /= static_cast<double>(k);
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
  for (const auto& p : points) {
    if (std::abs(pl->head<3>().dot(p) + (*pl)[3]) > band) continue;
    cov.noalias() += (p - mean) * (p - mean).transpose();
  }
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(cov);
  const Eigen::Vector3d n = eig.eigenvectors().col(0);  // smallest eigenvalue
  PlaneCoefficients next;
  next << n, -n.dot(mean);
  *pl = NormalizedPlane(next);
  return true;
}

}  // namespace

PlaneFit FitDominantPlane(const std::vector<Eigen::Vector3d>& points_world,
                          const PlaneFitOptions& options) {
  PlaneFit fit;
  fit.points = points_world.size();
  const std::size_t needed = std::max<std::size_t>(options.min_points, 3);
  if (points_world.size() < needed) {
    fit.error = "no target found: only " + std::to_string(points_world.size()) +
                " candidate points for the plane fit, at least " + std::to_string(needed) +
                " needed";
    return fit;
  }
  // Hypotheses are drawn from and scored on an evenly strided subsample (deterministic).
  const std::size_t stride = std::max<std::size_t>(
      1, points_world.size() / std::max<std::size_t>(1, options.max_scored_points));
  std::vector<Eigen::Vector3d> scored;
  for (std::size_t i = 0; i < points_world.size(); i += stride) scored.push_back(points_world[i]);
  std::mt19937_64 rng(options.seed);
  std::uniform_int_distribution<std::size_t> pick(0, scored.size() - 1);
  std::size_t best_support = 0;
  PlaneCoefficients best(0, 0, 1, 0);
  for (int it = 0; it < options.iterations; ++it) {
    const Eigen::Vector3d& a = scored[pick(rng)];
    const Eigen::Vector3d& b = scored[pick(rng)];
    const Eigen::Vector3d& c = scored[pick(rng)];
    const Eigen::Vector3d n = (b - a).cross(c - a);
    if (!(n.norm() > 1e-9)) continue;
    const Eigen::Vector3d unit = n.normalized();
    const double d = -unit.dot(a);
    std::size_t support = 0;
    for (const auto& p : scored) support += std::abs(unit.dot(p) + d) <= options.inlier_distance_m;
    if (support > best_support) {
      best_support = support;
      best << unit, d;
    }
  }
  if (best_support < 3) {
    fit.error = "no target found: the candidate points are degenerate (collinear or repeated)";
    return fit;
  }
  fit.plane = NormalizedPlane(best);
  for (int round = 0; round < 2; ++round) {
    if (!RefinePlane(points_world, options.inlier_distance_m, &fit.plane)) break;
  }
  double sum2 = 0.0;
  for (const auto& p : points_world) {
    const double dist = std::abs(fit.plane.head<3>().dot(p) + fit.plane[3]);
    if (dist > options.inlier_distance_m) continue;
    ++fit.inliers;
    sum2 += dist * dist;
  }
  fit.rms_m = fit.inliers > 0 ? std::sqrt(sum2 / static_cast<double>(fit.inliers)) : 0.0;
  const double share = static_cast<double>(fit.inliers) / static_cast<double>(fit.points);
  if (share < options.min_inlier_fraction) {
    char text[160];
    std::snprintf(text, sizeof text,
                  "no target found: the best plane holds only %.1f %% of the %zu candidate "
                  "points (at least %.0f %% needed)",
                  100.0 * share, fit.points, 100.0 * options.min_inlier_fraction);
    fit.error = text;
  }
  return fit;
}

namespace {

struct CellPoint {
  std::pair<std::int64_t, std::int64_t> cell;  // patch indices on the reference plane
  Eigen::Vector3d point_world;
  Eigen::Vector3d ray_world;
  double t = 0.0, r = 0.0;
};

// The samples of one cell's points [begin, end) against its own plane (see
// AppendLocalPlaneSamples); false when they are too few or degenerate for one.
bool AppendCell(const CellPoint* begin, const CellPoint* end, const Eigen::Vector3d& origin,
                const PlaneCoefficients& reference, std::size_t min_points,
                std::vector<RangeSample>* samples) {
  if (static_cast<std::size_t>(end - begin) < min_points) return false;
  std::vector<Eigen::Vector3d> points;
  points.reserve(static_cast<std::size_t>(end - begin));
  for (const CellPoint* c = begin; c != end; ++c) points.push_back(c->point_world);
  PlaneCoefficients local = reference;
  if (!RefinePlane(points, CalibrationOptions::kInfinity, &local)) return false;
  std::vector<double> distances;
  for (const auto& p : points) distances.push_back(std::abs(local.head<3>().dot(p) + local[3]));
  const double band = std::max(1e-5, 3.5 * kMadToSigma * Median(distances));
  if (!RefinePlane(points, band, &local)) return false;
  std::size_t kept = 0;
  for (const auto& p : points) kept += std::abs(local.head<3>().dot(p) + local[3]) <= band;
  if (kept < min_points) return false;
  const double scale = std::sqrt(static_cast<double>(kept) / static_cast<double>(kept - 3));
  const double origin_side = local.head<3>().dot(origin) + local[3];
  for (const CellPoint* c = begin; c != end; ++c) {
    const double cos_incidence = local.head<3>().dot(c->ray_world);
    if (std::abs(cos_incidence) < 1e-6) continue;
    const double t_local = -origin_side / cos_incidence;
    samples->push_back({c->t, c->t + (c->r - t_local) * scale});
  }
  return true;
}

}  // namespace

LocalSampleStats AppendLocalPlaneSamples(const float* points_xyz, std::size_t point_count,
                                         const Eigen::Isometry3d& T_world_sensor,
                                         const PlaneCoefficients& plane_world,
                                         const PlaneSampleOptions& options,
                                         const LocalPlaneOptions& local,
                                         std::vector<RangeSample>* samples) {
  CheckSampleArguments(points_xyz, point_count, samples, "AppendLocalPlaneSamples");
  if (!(local.patch_m > 0.0) || local.min_points < 4) {
    throw std::invalid_argument("AppendLocalPlaneSamples: patch_m must be > 0, min_points >= 4");
  }
  const PlaneCoefficients plane = NormalizedPlane(plane_world);
  const Eigen::Vector3d e1 = plane.head<3>().unitOrthogonal();
  const Eigen::Vector3d e2 = plane.head<3>().cross(e1);
  LocalSampleStats stats;
  stats.plane.points = point_count;
  std::vector<CellPoint> on_plane;
  for (std::size_t i = 0; i < point_count; ++i) {
    const PlaneReading hit = ReadPlane(points_xyz + 3 * i, T_world_sensor, plane, options);
    if (hit.counter != &PlaneSampleStats::samples) {
      ++(stats.plane.*hit.counter);
      continue;
    }
    CellPoint c;
    c.point_world = T_world_sensor.translation() + hit.r * hit.ray_world;
    c.cell = {static_cast<std::int64_t>(std::floor(e1.dot(c.point_world) / local.patch_m)),
              static_cast<std::int64_t>(std::floor(e2.dot(c.point_world) / local.patch_m))};
    c.ray_world = hit.ray_world;
    c.t = hit.t;
    c.r = hit.r;
    on_plane.push_back(c);
  }
  std::sort(on_plane.begin(), on_plane.end(),
            [](const CellPoint& a, const CellPoint& b) { return a.cell < b.cell; });
  const std::size_t before = samples->size();
  for (std::size_t i = 0, j = 0; i < on_plane.size(); i = j) {
    while (j < on_plane.size() && on_plane[j].cell == on_plane[i].cell) ++j;
    const CellPoint* cell = on_plane.data();
    if (AppendCell(cell + i, cell + j, T_world_sensor.translation(), plane, local.min_points,
                   samples)) {
      ++stats.cells;
    } else {
      stats.sparse += j - i;
    }
  }
  stats.plane.samples = samples->size() - before;
  return stats;
}

Calibration WithLocalNoise(const Calibration& reference, const Calibration& local) {
  if (!reference.ok() || !local.ok()) {
    throw std::invalid_argument("WithLocalNoise: both fits must have succeeded");
  }
  Calibration out = reference;
  out.q_sigma = local.q_sigma;
  out.epsilon = local.epsilon;
  for (CalibrationBin& bin : out.bins) {
    bin.fitted_sigma_m = out.q_sigma(bin.centre_m);
    bin.measured_sigma_m = std::numeric_limits<double>::quiet_NaN();
    for (const CalibrationBin& l : local.bins) {
      if (bin.centre_m >= l.begin_m && bin.centre_m <= l.end_m) {
        bin.measured_sigma_m = l.measured_sigma_m;
        break;
      }
    }
  }
  return out;
}

}  // namespace fusion
