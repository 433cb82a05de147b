// The dense beam (paper Sec. II-C, every p(B_i) stored): obvious and slow, the oracle of the
// unrolled linked list (ull_beam.cc).
#include <algorithm>
#include <cmath>

#include "beam_store_of.h"
#include "fusion/core/beam.h"

namespace fusion {

DenseBeam::DenseBeam(const BeamContext& ctx) { Reset(ctx); }

void DenseBeam::Reset(const BeamContext& ctx) {
  const std::size_t n = ctx.cell_count();
  p_.resize(n + 1);
  // Eq. 7 with p(m_i) = p0 for every cell.
  for (std::size_t i = 0; i < n; ++i) p_[i] = ctx.prior() * ctx.RhoPow(i);
  p_[n] = ctx.RhoPow(n);
  touched_ = false;
}

double DenseBeam::Update(const BeamContext& ctx, std::size_t outcome) {
  const ForwardModel& model = ctx.model();
  // The ROI mass before the update, of the visible mass (blind cells hold none once touched).
  const std::size_t n = ctx.cell_count();
  double visible = 0.0;
  for (std::size_t i = std::min(ctx.disc().first_visible_cell, n); i <= n; ++i) visible += p_[i];
  double roi_sum = -1.0;
  if (outcome == ctx.disc().beyond_outcome()) {
    roi_sum = p_[n];
  } else if (const BeamContext::RoiFactors roi = ctx.Roi(outcome); roi.end > roi.begin) {
    roi_sum = 0.0;
    for (std::size_t i = roi.begin; i < roi.end; ++i) roi_sum += p_[i];
  }
  const double mass = roi_sum < 0.0 ? -1.0 : roi_sum / visible;
  double sum = 0.0;
  for (std::size_t i = 0; i < p_.size(); ++i) {
    p_[i] *= model.Probability(i, outcome);  // Eq. 11 numerator
    sum += p_[i];
  }
  touched_ = true;
  if (!(sum > 0.0) || !std::isfinite(sum)) {  // impossible outcome under p(B): start afresh
    Reset(ctx);
    touched_ = true;
    return mass;
  }
  const double eta = 1.0 / sum;  // Eq. 11 normaliser
  for (double& p : p_) p *= eta;
  return mass;
}

void DenseBeam::Weights(const BeamContext& /*ctx*/, std::vector<double>* weights) const {
  *weights = p_;
}

void DenseBeam::TailMasses(const BeamContext& ctx, const std::uint32_t* cells, std::size_t count,
                           double* out) const {
  const std::size_t n = ctx.cell_count();
  double acc = p_[n];
  std::size_t i = n;
  for (std::size_t j = count; j-- > 0;) {
    const std::size_t target = std::min<std::size_t>(cells[j], n);
    while (i > target) acc += p_[--i];
    out[j] = acc;
  }
}

void DenseBeam::TailSpan(const BeamContext& ctx, std::uint32_t first, std::uint32_t last,
                         std::vector<double>* out, double* total) const {
  const std::size_t n = ctx.cell_count();
  out->resize(last - first + 1);
  double acc = p_[n];
  for (std::size_t i = n; i-- > last;) acc += p_[i];  // S(last)
  (*out)[last - first] = acc;
  for (std::size_t c = last; c-- > first;) (*out)[c - first] = acc += p_[c];
  for (std::size_t i = first; i-- > 0;) acc += p_[i];
  *total = acc;
}

std::uint32_t DenseBeam::TailDropCell(const BeamContext& ctx, std::uint32_t from,
                                      double fraction) const {
  const std::size_t n = ctx.cell_count();
  const std::size_t start = std::min<std::size_t>(from, n);
  double tail_from = 0.0;
  for (std::size_t i = n + 1; i-- > start;) tail_from += p_[i];
  const double threshold = fraction * tail_from;
  double acc = p_[n];
  if (acc >= threshold) return static_cast<std::uint32_t>(n + 1);
  for (std::size_t i = n; i-- > start;) {
    acc += p_[i];
    if (acc >= threshold) return static_cast<std::uint32_t>(i + 1);
  }
  return static_cast<std::uint32_t>(start + 1);  // fraction >= 1
}

BeamProfileCells DenseBeam::Profile(const BeamContext& ctx, std::uint32_t from,
                                    double tail_fraction, double free_ratio) const {
  const std::size_t n = ctx.cell_count();
  const std::size_t start = std::min<std::size_t>(from, n);
  std::vector<double> tail(n + 1);  // S(c), c in [0, N]
  double acc = p_[n];
  tail[n] = acc;
  for (std::size_t i = n; i-- > 0;) tail[i] = acc += p_[i];
  BeamProfileCells out;
  out.info_end = TailDropCell(ctx, from, tail_fraction);
  const double no_information = kNoInformationTail * tail[0];
  std::size_t c = start;
  while (c < n && tail[c] > no_information && p_[c] <= free_ratio * ctx.prior() * tail[c]) ++c;
  out.mass_begin = static_cast<std::uint32_t>(c < n ? c : n + 1);
  out.free_hazard = tail[start] > 0.0 && c > start ? -std::log(tail[c] / tail[start]) : 0.0;
  out.median = TailDropCell(ctx, from, 0.5);
  return out;
}

std::size_t DenseBeam::MemoryBytes() const {
  return sizeof(*this) + p_.capacity() * sizeof(double);
}

// Instantiated here, next to DenseBeam::Update, which then inlines into UpdateMany.
std::unique_ptr<BeamStore> detail::MakeDenseBeamStore(std::shared_ptr<const BeamContext> context,
                                                      std::size_t beam_count) {
  return std::make_unique<detail::BeamStoreOf<DenseBeam>>(std::move(context), beam_count);
}

}  // namespace fusion
