// What both beam representations share (paper Sec. II-C): the prior, Eqs. 7 and 8 on whole
// beams, the per-sensor BeamContext, and the choice of store. The representations themselves:
// dense_beam.cc (the oracle) and ull_beam.cc (the paper's unrolled linked list, Sec. IV-A).
#include "fusion/core/beam.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>
#include <utility>

#include "beam_store_of.h"

namespace fusion {
namespace {

// Largest ULL factor table (entries); beyond it factors are computed on the fly.
constexpr std::size_t kMaxTableEntries = std::size_t{1} << 25;

// The prior cell occupancy the options give (ResolvePriorCellOccupancy), or NaN with *why set.
double PriorOf(const BeamGridOptions& options, std::string* why) {
  double p0 = options.prior_cell_occupancy;
  if (p0 < 0.0) {
    if (!(options.prior_reference_length_m > 0.0) ||
        !std::isfinite(options.prior_reference_length_m)) {
      *why = "prior_reference_length_m must be finite and > 0";
      return std::numeric_limits<double>::quiet_NaN();
    }
    p0 = 1.0 - std::pow(0.5, options.cell_size_m / options.prior_reference_length_m);
  }
  if (!(p0 > 0.0 && p0 < 1.0)) {
    *why = "prior cell occupancy must lie in (0, 1)";
    return std::numeric_limits<double>::quiet_NaN();
  }
  return p0;
}

}  // namespace

double ResolvePriorCellOccupancy(const BeamGridOptions& options) {
  std::string why;
  const double p0 = PriorOf(options, &why);
  if (std::isnan(p0)) throw std::invalid_argument(why);
  return p0;
}

bool BeamGridOptions::IsValid(std::string* why) const {
  std::string local;
  std::string& out = why != nullptr ? *why : local;
  if (!(cell_size_m >= kMinCellSizeM && cell_size_m <= kMaxCellSizeM)) {
    out = "cell_size_m must lie in [0.0001, 1] m";
    return false;
  }
  if (change_run > 100) {
    out = "change_run must lie in 0..100 (0: off)";
    return false;
  }
  if (!(change_min_mass > 0.0 && change_min_mass < 1.0)) {
    out = "change_min_mass must lie in (0, 1)";
    return false;
  }
  if (!(prior_cell_occupancy < 0.0 || (prior_cell_occupancy > 0.0 && prior_cell_occupancy < 1.0))) {
    out = "prior_cell_occupancy must lie in (0, 1), or be negative (from the reference length)";
    return false;
  }
  if (std::isnan(PriorOf(*this, &out))) {
    // The explicit occupancy passed above: the reference length is bad, or the prior it gives
    // at this cell size is 0 or 1.
    if (out.rfind("prior_reference_length_m", 0) != 0) {
      out =
          "prior_reference_length_m gives a prior cell occupancy outside (0, 1) at this cell "
          "size";
    }
    return false;
  }
  return true;
}

std::vector<double> FirstHitFromCells(const std::vector<double>& p_m) {
  std::vector<double> p_b(p_m.size() + 1);
  double all_free_so_far = 1.0;  // prod_{j<i} (1 - p(m_j))
  for (std::size_t i = 0; i < p_m.size(); ++i) {
    p_b[i] = p_m[i] * all_free_so_far;
    all_free_so_far *= 1.0 - p_m[i];
  }
  p_b.back() = all_free_so_far;
  return p_b;
}

std::vector<double> CellsFromFirstHit(const std::vector<double>& weights,
                                      double no_information_value) {
  if (weights.empty()) return {};
  const std::size_t n = weights.size() - 1;
  std::vector<double> tail(n + 1);
  double acc = weights[n];
  tail[n] = acc;
  for (std::size_t i = n; i-- > 0;) {
    acc += weights[i];
    tail[i] = acc;
  }
  const double threshold = kNoInformationTail * tail[0];
  std::vector<double> p_m(n);
  for (std::size_t i = 0; i < n; ++i) {
    // Eq. 8: 1 - sum_{j<i} p(B_j) is the tail mass from i on (total normalised to 1).
    p_m[i] = tail[i] > threshold ? std::min(1.0, weights[i] / tail[i]) : no_information_value;
  }
  return p_m;
}

// ---------------------------------------------------------------------------------------------
// BeamContext

BeamContext::BeamContext(const SensorSpec& spec, const BeamGridOptions& options)
    : model_(MakeForwardModel(spec, options.cell_size_m)),
      prior_(ResolvePriorCellOccupancy(options)) {
  const std::size_t n = cell_count();
  const double r = rho();
  rho_pow_.resize(n + 1);
  geom_sum_.resize(n + 2);
  geom_sum_[0] = 0.0;
  for (std::size_t j = 0; j <= n; ++j) {
    rho_pow_[j] = std::pow(r, static_cast<double>(j));
    geom_sum_[j + 1] = geom_sum_[j] + rho_pow_[j];
  }
  // ROI spans, B_{N+1} factors and the factor table, outcome by outcome.
  const std::size_t outcomes = disc().outcome_count();
  roi_begin_.resize(outcomes);
  roi_end_.resize(outcomes);
  all_free_factor_.resize(outcomes);
  std::size_t entries = 0;
  for (std::size_t o = 0; o < outcomes; ++o) {
    const CellSpan span = model_->Roi(o);
    const std::size_t b = std::max(span.begin, disc().first_visible_cell);
    const std::size_t e = std::min(span.end, n);
    roi_begin_[o] = static_cast<std::uint32_t>(e > b ? b : 0);
    roi_end_[o] = static_cast<std::uint32_t>(e > b ? e : 0);
    entries += roi_end_[o] - roi_begin_[o];
    all_free_factor_[o] = Factor(n, o);
  }
  if (entries <= kMaxTableEntries) {
    table_offset_.resize(outcomes + 1);
    table_.resize(entries);
    std::size_t at = 0;
    for (std::size_t o = 0; o < outcomes; ++o) {
      table_offset_[o] = at;
      for (std::size_t i = roi_begin_[o]; i < roi_end_[o]; ++i) table_[at++] = Factor(i, o);
    }
    table_offset_[outcomes] = at;
  }
}

double BeamContext::Factor(std::size_t cell, std::size_t outcome) const {
  return model_->Probability(cell, outcome) / model_->OutsideRoiProbability(outcome);
}

std::size_t BeamContext::MemoryBytes() const {
  // The model's own per-cell / per-bin tables are small next to table_; counted roughly.
  const std::size_t n = cell_count();
  const std::size_t model_bytes = 6 * n * sizeof(double) + 2 * disc().bin_count * 4;
  return sizeof(*this) + model_bytes +
         (rho_pow_.capacity() + geom_sum_.capacity() + table_.capacity() +
          all_free_factor_.capacity()) *
             sizeof(double) +
         table_offset_.capacity() * sizeof(std::size_t) +
         (roi_begin_.capacity() + roi_end_.capacity()) * sizeof(std::uint32_t);
}

// ---------------------------------------------------------------------------------------------
// BeamStore

std::unique_ptr<BeamStore> MakeBeamStore(BeamRepresentation representation,
                                         std::shared_ptr<const BeamContext> context,
                                         std::size_t beam_count) {
  if (representation == BeamRepresentation::kDense) {
    return detail::MakeDenseBeamStore(std::move(context), beam_count);
  }
  return detail::MakeUllBeamStore(std::move(context), beam_count);
}

}  // namespace fusion
