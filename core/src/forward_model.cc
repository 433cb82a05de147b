// Discrete forward models: the paper's Algorithm III.1 and the classic beam model.
#include "fusion/core/forward_model.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

namespace fusion {
namespace {

constexpr double kInvSqrt2Pi = 0.39894228040143267794;
constexpr double kInvSqrt2 = 0.70710678118654752440;
// Guards ceil() against 21 = 1 / (1/21) coming out as 21.000000000000004.
constexpr double kRoundingSlack = 1e-9;
// Largest beam we accept (cells are indexed with 32 bits in the beam stores).
constexpr double kMaxCells = 1e8;
// Smallest standard deviation used when q_sigma is not positive at a visible cell.
constexpr double kMinSigmaM = 1e-6;

std::size_t CeilCount(double length_m, double cell_size_m) {
  const double n = std::ceil(length_m / cell_size_m - kRoundingSlack);
  return static_cast<std::size_t>(std::max(1.0, n));
}

void CheckInputs(const SensorSpec& spec, double cell_size_m) {
  const std::string why = ValidateSensorSpec(spec);
  if (!why.empty()) throw std::invalid_argument("invalid sensor spec: " + why);
  if (!(cell_size_m > 0.0) || !std::isfinite(cell_size_m)) {
    throw std::invalid_argument("cell_size_m must be finite and > 0");
  }
  if (spec.r_max_m / cell_size_m > kMaxCells) {
    throw std::invalid_argument("beam too long for the cell size (more than 1e8 cells)");
  }
}

std::size_t FirstVisibleCell(double r_min_m, double cell_size_m, std::size_t cells) {
  std::size_t i = 0;
  const double guess = std::floor(r_min_m / cell_size_m - 0.5) - 1.0;
  if (guess > 0.0) i = static_cast<std::size_t>(guess);
  while (i < cells && (static_cast<double>(i) + 0.5) * cell_size_m < r_min_m) ++i;
  return std::min(i, cells);
}

double Phi(double x) { return 0.5 * std::erfc(-x * kInvSqrt2); }

}  // namespace

std::size_t CellsPerBeam(double r_max_m, double cell_size_m) {
  return CeilCount(r_max_m, cell_size_m);
}

double NormalDensity(double r, double mu, double sigma) {
  const double z = (r - mu) / sigma;
  return kInvSqrt2Pi / sigma * std::exp(-0.5 * z * z);
}

std::optional<std::size_t> BeamDiscretisation::OutcomeOf(const Reading& reading) const {
  switch (reading.kind) {
    case Reading::Kind::kMissing:
      return std::nullopt;
    case Reading::Kind::kBeyondRange:
      return beyond_outcome();
    case Reading::Kind::kRange:
      break;
  }
  const double r = reading.range_m;
  if (!std::isfinite(r) || r < 0.0) return std::nullopt;
  if (r > r_limit_m) return beyond_outcome();
  const double k = std::floor(r / cell_size_m);
  return std::min(static_cast<std::size_t>(k), bin_count - 1);
}

// ---------------------------------------------------------------------------------------------
// Paper 3D model.

Paper3dModel::Paper3dModel(const SensorSpec& spec, double cell_size_m) {
  CheckInputs(spec, cell_size_m);
  eps_ = spec.epsilon;
  delta_sigmas_ = spec.delta;
  BeamDiscretisation& d = disc_;
  d.cell_size_m = cell_size_m;
  d.cell_count = CellsPerBeam(spec.r_max_m, cell_size_m);
  d.first_visible_cell = FirstVisibleCell(spec.r_min_m, cell_size_m, d.cell_count);
  const std::size_t n = d.cell_count;
  mu_m_.resize(n);
  sigma_m_.resize(n);
  inv_sigma_.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    const double range = d.CellRange(i);
    mu_m_[i] = spec.q_mu(range);
    sigma_m_[i] = std::max(spec.q_sigma(range), kMinSigmaM);
    inv_sigma_[i] = 1.0 / sigma_m_[i];
  }
  // Algorithm III.1 line 1.
  d.r_limit_m = mu_m_[n - 1] + delta_sigmas_ * sigma_m_[n - 1];
  if (!(d.r_limit_m > 0.0)) d.r_limit_m = d.CellRange(n - 1);
  d.bin_count = CeilCount(d.r_limit_m, cell_size_m);
  const std::size_t k_count = d.bin_count;
  eps_bin_ = eps_ / static_cast<double>(k_count + 1);

  roi_begin_.assign(k_count, std::numeric_limits<std::uint32_t>::max());
  roi_end_.assign(k_count, 0);
  for (std::size_t i = d.first_visible_cell; i < n; ++i) {
    const double half = delta_sigmas_ * sigma_m_[i];
    const double lo = std::floor((mu_m_[i] - half) / cell_size_m) - 1.0;
    const double hi = std::floor((mu_m_[i] + half) / cell_size_m) + 1.0;
    if (hi < 0.0 || lo >= static_cast<double>(k_count)) continue;
    const std::size_t k_lo = lo <= 0.0 ? 0 : static_cast<std::size_t>(lo);
    const std::size_t k_hi = std::min(k_count - 1, static_cast<std::size_t>(hi));
    for (std::size_t k = k_lo; k <= k_hi; ++k) {
      if (!InRoi(i, k)) continue;
      roi_begin_[k] = std::min<std::uint32_t>(roi_begin_[k], static_cast<std::uint32_t>(i));
      roi_end_[k] = std::max<std::uint32_t>(roi_end_[k], static_cast<std::uint32_t>(i + 1));
    }
  }
  for (std::size_t k = 0; k < k_count; ++k) {
    if (roi_end_[k] == 0) roi_begin_[k] = 0;
  }
}

bool Paper3dModel::InRoi(std::size_t cell, std::size_t bin) const {
  const double half = delta_sigmas_ * sigma_m_[cell];
  const double lo = std::max(static_cast<double>(bin) * disc_.cell_size_m, mu_m_[cell] - half);
  const double hi = std::min(static_cast<double>(bin + 1) * disc_.cell_size_m, mu_m_[cell] + half);
  return hi > lo;
}

double Paper3dModel::RoiMass(std::size_t cell, std::size_t bin) const {
  const double half = delta_sigmas_ * sigma_m_[cell];
  const double lo = std::max(static_cast<double>(bin) * disc_.cell_size_m, mu_m_[cell] - half);
  const double hi = std::min(static_cast<double>(bin + 1) * disc_.cell_size_m, mu_m_[cell] + half);
  if (!(hi > lo)) return 0.0;
  const double a = (lo - mu_m_[cell]) * inv_sigma_[cell];
  const double b = (hi - mu_m_[cell]) * inv_sigma_[cell];
  // Phi(b) - Phi(a) from the nearer tail, so that neither side cancels.
  if (a >= 0.0) return 0.5 * (std::erfc(a * kInvSqrt2) - std::erfc(b * kInvSqrt2));
  if (b <= 0.0) return 0.5 * (std::erfc(-b * kInvSqrt2) - std::erfc(-a * kInvSqrt2));
  return 1.0 - 0.5 * (std::erfc(-a * kInvSqrt2) + std::erfc(b * kInvSqrt2));
}

double Paper3dModel::Probability(std::size_t cell, std::size_t outcome) const {
  const std::size_t n = disc_.cell_count;
  const std::size_t beyond = disc_.beyond_outcome();
  if (cell >= n) {  // B_{N+1}: Eqs. 13, 14 (Algorithm III.1 lines 2, 3)
    return outcome >= beyond ? 1.0 - eps_ : eps_ / static_cast<double>(disc_.bin_count);
  }
  if (cell < disc_.first_visible_cell) return 0.0;  // blind
  if (outcome >= beyond) return eps_bin_;           // Eq. 12 up to the eps floor
  if (!InRoi(cell, outcome)) return eps_bin_;
  return (1.0 - eps_) * RoiMass(cell, outcome);
}

CellSpan Paper3dModel::Roi(std::size_t outcome) const {
  if (outcome >= disc_.bin_count) return {};
  return {roi_begin_[outcome], roi_end_[outcome]};
}

double Paper3dModel::OutsideRoiProbability(std::size_t /*outcome*/) const { return eps_bin_; }

// ---------------------------------------------------------------------------------------------
// Classic beam model.

ClassicBeamModel::ClassicBeamModel(const SensorSpec& spec, double cell_size_m) {
  CheckInputs(spec, cell_size_m);
  p_ = spec.classic;
  const double sum = p_.z_hit + p_.z_short + p_.z_max + p_.z_rand;
  p_.z_hit /= sum;
  p_.z_short /= sum;
  p_.z_max /= sum;
  p_.z_rand /= sum;
  BeamDiscretisation& d = disc_;
  d.cell_size_m = cell_size_m;
  d.cell_count = CellsPerBeam(spec.r_max_m, cell_size_m);
  d.first_visible_cell = FirstVisibleCell(spec.r_min_m, cell_size_m, d.cell_count);
  d.r_limit_m = spec.r_max_m;  // z_max_range
  d.bin_count = CeilCount(spec.r_max_m, cell_size_m);
  const double top = static_cast<double>(d.bin_count) * cell_size_m;
  hit_norm_.resize(d.cell_count);
  short_norm_.resize(d.cell_count + 1);
  for (std::size_t i = 0; i < d.cell_count; ++i) {
    const double range = d.CellRange(i);
    const double mass = Phi((top - range) / p_.sigma_hit_m) - Phi(-range / p_.sigma_hit_m);
    hit_norm_[i] = mass > 0.0 ? 1.0 / mass : 0.0;
    short_norm_[i] = 1.0 / -std::expm1(-p_.lambda_short_per_m * range);
  }
  short_norm_[d.cell_count] = 1.0 / -std::expm1(-p_.lambda_short_per_m * top);
}

double ClassicBeamModel::Probability(std::size_t cell, std::size_t outcome) const {
  const std::size_t n = disc_.cell_count;
  const bool all_free = cell >= n;
  if (!all_free && cell < disc_.first_visible_cell) return 0.0;
  if (outcome >= disc_.beyond_outcome()) return p_.z_max + (all_free ? p_.z_hit : 0.0);
  const double a = static_cast<double>(outcome) * disc_.cell_size_m;
  const double b = a + disc_.cell_size_m;
  const double lambda = p_.lambda_short_per_m;
  double p = p_.z_rand / static_cast<double>(disc_.bin_count);
  if (all_free) {
    p += p_.z_short * (std::exp(-lambda * a) - std::exp(-lambda * b)) * short_norm_[n];
    return p;
  }
  const double range = disc_.CellRange(cell);
  const double s = p_.sigma_hit_m;
  p += p_.z_hit * (Phi((b - range) / s) - Phi((a - range) / s)) * hit_norm_[cell];
  if (a < range) {
    const double top = std::min(b, range);
    p += p_.z_short * (std::exp(-lambda * a) - std::exp(-lambda * top)) * short_norm_[cell];
  }
  return p;
}

CellSpan ClassicBeamModel::Roi(std::size_t /*outcome*/) const {
  return {disc_.first_visible_cell, disc_.cell_count};
}

std::unique_ptr<ForwardModel> MakeForwardModel(const SensorSpec& spec, double cell_size_m) {
  switch (spec.model) {
    case ForwardModelKind::kClassicBeam:
      return std::make_unique<ClassicBeamModel>(spec, cell_size_m);
    case ForwardModelKind::kPaper3d:
      break;
  }
  return std::make_unique<Paper3dModel>(spec, cell_size_m);
}

}  // namespace fusion
