// Beam state p(B_1..B_{N+1}) and its Bayesian update (paper Eqs. 7, 8, 11), in two
// representations behind one interface (BeamStore):
//   - DenseBeam: every p(B_i) stored as a normalised double; obvious and slow; the oracle.
//   - UllBeam: the paper's unrolled linked list (Sec. IV-A) of composite cells, each exploded
//     (EC, per-cell values in a pooled vector) or unexploded (UEC, updated as a whole).
// See docs/forward-model.md for the discrete form and the reasons behind each choice.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <vector>

#include "fusion/core/beam_types.h"
#include "fusion/core/forward_model.h"
#include "fusion/core/sensor.h"

namespace fusion {

// A tail mass S_i = sum_{j >= i} p(B_j) (B_{N+1} included) at or below this fraction of the
// beam's total mass means "no information" about cell i (Eq. 8 with a vanishing denominator):
// the cell reports the prior. A numerical tolerance for the paper's exact zero; it also keeps
// the two representations (which underflow at different points) in agreement.
inline constexpr double kNoInformationTail = 1e-100;

// Resolves BeamGridOptions::prior_cell_occupancy (negative = default from the reference
// length). Throws std::invalid_argument unless the result lies in (0, 1).
[[nodiscard]] double ResolvePriorCellOccupancy(const BeamGridOptions& options);

// What a renderer needs of one beam from a start cell `from` on (BeamStore::Profile):
//   mass_begin: the first cell c >= from whose p(m_c) exceeds free_ratio * p0 (the first-hit
//               mass starts there; cells before it are the beam's free zone), N + 1 if none;
//   info_end:   the smallest cell c in (from, N] with S(c) < tail_fraction * S(from)
//               (TailDropCell), N + 1 if none;
//   free_hazard: -log(S(end) / S(from)) over the free zone [from, end), end = min(mass_begin,
//               N): the zone's cumulative hazard, to compare with the prior's (0 if empty);
//   median:     TailDropCell(from, 0.5): where the first hit is as likely before as after.
// A cell without information (S <= kNoInformationTail * total) ends the free zone.
struct BeamProfileCells {
  std::uint32_t mass_begin = 0;
  std::uint32_t info_end = 0;
  double free_hazard = 0.0;
  std::uint32_t median = 0;
};

// Eq. 7: p(B) (N + 1 values) from p(m) (N values).
[[nodiscard]] std::vector<double> FirstHitFromCells(const std::vector<double>& p_m);
// Eq. 8 on (possibly unnormalised) p(B) weights (N + 1 values); tails are summed from the far
// end. Cells without information (tail <= kNoInformationTail * total) get no_information_value.
[[nodiscard]] std::vector<double> CellsFromFirstHit(const std::vector<double>& weights,
                                                    double no_information_value);

// Read-only per-sensor data shared by every beam of a grid: the forward model, prior powers
// and the ULL factor table (p(o | B_i) / OutsideRoiProbability(o) for the ROI cells of every
// reading bin), so that a reading costs ROI-width multiplications and no exp().
class BeamContext {
 public:
  BeamContext(const SensorSpec& spec, const BeamGridOptions& options);

  [[nodiscard]] const ForwardModel& model() const { return *model_; }
  [[nodiscard]] const BeamDiscretisation& disc() const { return model_->discretisation(); }
  [[nodiscard]] std::size_t cell_count() const { return disc().cell_count; }
  [[nodiscard]] double prior() const { return prior_; }  // p0
  [[nodiscard]] double rho() const { return 1.0 - prior_; }
  [[nodiscard]] double RhoPow(std::size_t j) const { return rho_pow_[j]; }    // j <= N
  [[nodiscard]] double GeomSum(std::size_t m) const { return geom_sum_[m]; }  // sum_{j<m} rho^j
  [[nodiscard]] const double* GeomSums() const { return geom_sum_.data(); }   // GeomSum(0..N)

  // ROI of an outcome, clamped to the visible cells, with the relative factors
  // p(o | B_i) / OutsideRoiProbability(o) (nullptr when not tabulated: use Factor()).
  struct RoiFactors {
    std::size_t begin = 0;
    std::size_t end = 0;
    const double* factors = nullptr;
  };
  [[nodiscard]] RoiFactors Roi(std::size_t outcome) const {
    RoiFactors roi{roi_begin_[outcome], roi_end_[outcome], nullptr};
    if (!table_.empty() && roi.end > roi.begin)
      roi.factors = table_.data() + table_offset_[outcome];
    return roi;
  }
  [[nodiscard]] double Factor(std::size_t cell, std::size_t outcome) const;
  // Relative factor of B_{N+1}.
  [[nodiscard]] double AllFreeFactor(std::size_t outcome) const {
    return all_free_factor_[outcome];
  }
  [[nodiscard]] std::size_t MemoryBytes() const;

 private:
  std::unique_ptr<ForwardModel> model_;
  double prior_ = 0.5;
  std::vector<double> rho_pow_, geom_sum_;
  std::vector<std::uint32_t> roi_begin_, roi_end_;  // per outcome, clamped to visible cells
  std::vector<double> all_free_factor_;             // per outcome
  std::vector<std::size_t> table_offset_;           // per outcome, into table_ (size outcomes + 1)
  std::vector<double> table_;                       // empty when the table would be too large
};

// Dense reference beam: p(B_1..B_{N+1}) normalised after every update.
class DenseBeam {
 public:
  explicit DenseBeam(const BeamContext& ctx);
  void Reset(const BeamContext& ctx);
  // Eq. 11 for one outcome; every cell evaluated through ForwardModel::Probability. Returns
  // the reading's ROI mass (the change detector's test, BeamGridOptions::change_run): the
  // p(B) mass before the update on the cells that explain the outcome (its ROI; B_{N+1} for a
  // beyond-range reading), a fraction of the beam's visible mass; -1 if no cell explains it.
  double Update(const BeamContext& ctx, std::size_t outcome);
  void Weights(const BeamContext& ctx, std::vector<double>* weights) const;  // N + 1
  // S(c) = mass of cells >= c plus B_{N+1}, for `count` ascending c in [0, N], into out[].
  void TailMasses(const BeamContext& ctx, const std::uint32_t* cells, std::size_t count,
                  double* out) const;
  // S(c) for every c in [first, last] (last <= N) into out[c - first], and S(0) into *total.
  void TailSpan(const BeamContext& ctx, std::uint32_t first, std::uint32_t last,
                std::vector<double>* out, double* total) const;
  // The smallest cell c in (from, N] with S(c) < fraction * S(from); N + 1 if there is none.
  [[nodiscard]] std::uint32_t TailDropCell(const BeamContext& ctx, std::uint32_t from,
                                           double fraction) const;
  // The reference: every cell evaluated.
  [[nodiscard]] BeamProfileCells Profile(const BeamContext& ctx, std::uint32_t from,
                                         double tail_fraction, double free_ratio) const;
  [[nodiscard]] bool touched() const { return touched_; }
  [[nodiscard]] std::size_t MemoryBytes() const;
  void Prefetch() const {}

 private:
  std::vector<double> p_;
  bool touched_ = false;
};

// Unrolled linked list beam. Weights are kept UNNORMALISED with a running total; an update
// touches only the ROI cells (relative factor), B_{N+1} and the total, and renormalises only
// when the total leaves [kLowTotal, kHighTotal]. A UEC holds a geometric run of weights
// w_j = w_first * rho^(j - first) (the prior's shape, preserved by the constant out-of-ROI
// factor), so its sums have closed forms. EC values live in one pooled vector kept in list
// order, so adjacent ECs always merge and the list alternates UEC / EC.
class UllBeam {
 public:
  struct Composite {
    std::uint32_t first = 0;       // first cell
    std::uint32_t count = 0;       // cells
    std::uint32_t pool_begin = 0;  // EC: offset of its values; UEC: where an EC here would go
    std::uint32_t exploded = 0;    // 1 = EC, 0 = UEC
    double w_first = 0.0;          // UEC: weight of its first cell
  };
  static constexpr double kLowTotal = 1e-150;
  static constexpr double kHighTotal = 1e150;

  explicit UllBeam(const BeamContext& ctx);
  void Reset(const BeamContext& ctx);
  // As DenseBeam::Update (the ROI mass comes out of the update's own loop).
  double Update(const BeamContext& ctx, std::size_t outcome);
  void Weights(const BeamContext& ctx, std::vector<double>* weights) const;  // N + 1, unnormalised
  void TailMasses(const BeamContext& ctx, const std::uint32_t* cells, std::size_t count,
                  double* out) const;
  // As DenseBeam::TailSpan: one walk of the list, a running sum through the span.
  void TailSpan(const BeamContext& ctx, std::uint32_t first, std::uint32_t last,
                std::vector<double>* out, double* total) const;
  // As DenseBeam::TailDropCell; walks the list from the far end and stops at the crossing.
  [[nodiscard]] std::uint32_t TailDropCell(const BeamContext& ctx, std::uint32_t from,
                                           double fraction) const;
  // As DenseBeam::Profile, composite by composite: a UEC's p(m) falls along the run while it
  // lies below p0 (w_{j+1} / S_{j+1} < w_j / S_j iff w_j < p0 S_j), so only its first cell is
  // tested; an EC is tested cell by cell.
  [[nodiscard]] BeamProfileCells Profile(const BeamContext& ctx, std::uint32_t from,
                                         double tail_fraction, double free_ratio) const;
  [[nodiscard]] bool touched() const { return touched_; }
  [[nodiscard]] std::size_t MemoryBytes() const;
  // Hints the cache about the memory the next Update will touch (no effect on results).
  void Prefetch() const;

  [[nodiscard]] const std::vector<Composite>& composites() const { return list_; }
  [[nodiscard]] std::size_t exploded_cell_count() const { return pool_.size(); }
  [[nodiscard]] double running_total() const { return total_; }
  // Composite forward model of composite `index` (Eq. 17): the p(B)-weighted average of its
  // cells' p(outcome | B_ij), by Simpson's three-point rule on the first, middle and last
  // cell (exact for an EC: plain weighted sum). For a UEC outside every ROI the cells' model
  // is constant, so the rule is exact there.
  [[nodiscard]] double CompositeModel(const BeamContext& ctx, std::size_t index,
                                      std::size_t outcome) const;
  // Exact Eq. 17 (every cell) for comparison.
  [[nodiscard]] double CompositeModelExact(const BeamContext& ctx, std::size_t index,
                                           std::size_t outcome) const;

 private:
  std::size_t Find(std::size_t cell) const;  // composite containing cell
  // Makes [begin, end) part of one EC (splitting UECs into <= 3 pieces); returns its index.
  std::size_t Explode(const BeamContext& ctx, std::size_t begin, std::size_t end);
  double CompositeSum(const BeamContext& ctx, const Composite& c) const;
  void Renormalise(const BeamContext& ctx);
  void Resum(const BeamContext& ctx);  // total_ summed exactly again (no weight changes)
  [[nodiscard]] double ExactTotal(const BeamContext& ctx) const;  // every weight, summed
  // Profile's steps. S at the start of every composite (s_at[k], k < list size) and after the
  // last one (s_at[list size], B_{N+1} alone).
  void TailsAtComposites(const BeamContext& ctx, double* s_at) const;
  // The free zone from cell `start` on: sets out->mass_begin; returns S(start) (negative if
  // start == N) and S where the zone ends.
  struct FreeZoneTails {
    double s_start;
    double s_end;
  };
  FreeZoneTails ScanFreeZone(const BeamContext& ctx, const double* s_at, std::size_t start,
                             double free_ratio, BeamProfileCells* out) const;
  // TailDropCell from s_at: the first cell after `start` where S falls below
  // fraction * s_start (N + 1 if B_{N+1} alone holds that much).
  std::uint32_t FirstCellBelow(const BeamContext& ctx, const double* s_at, std::size_t start,
                               double s_start, double fraction) const;
  // An exploded composite's cells below t added to *tail from the top down until it reaches
  // threshold: the cell (relative to the composite) where it did, or 0.
  std::size_t WalkDown(const Composite& c, std::size_t t, double threshold, double* tail) const;
  // out->info_end and out->median: FirstCellBelow at tail_fraction and at 1/2, in one walk of
  // the exploded composite where both fall in the same one.
  void InfoEndAndMedian(const BeamContext& ctx, const double* s_at, std::size_t start,
                        double s_start, double tail_fraction, BeamProfileCells* out) const;

  std::vector<Composite> list_;
  std::vector<double> pool_;
  double w_all_free_ = 0.0;  // B_{N+1}
  double total_ = 1.0;
  // A bound on |total_ - the weights' exact sum|: the total is summed afresh (Resum) before
  // it exceeds kMaxTotalError of the total, and an EC's sum is derived from it (total_ less
  // the rest, as TailsAtComposites does) only while it is within kDerivedError of that sum.
  double total_error_ = 0.0;
  static constexpr double kSumError = 1e-13;    // of a fresh sum
  static constexpr double kUpdateError = 1e-13;  // of an update, per unit of weight
  static constexpr double kMaxTotalError = 1e-11;
  static constexpr double kDerivedError = 1e-8;
  static constexpr double kRoundingError = 1e-16;  // of a sum, per term, of the sum
  static constexpr double kTailError = 1e-9;       // TailMasses' tolerance, of each tail
  bool touched_ = false;
  // The EC of the last update ([ec_first_, ec_end_) at pool offset ec_pool_; ec_end_ = 0: none):
  // a steady-state update whose ROI lies inside it needs neither the list nor a search.
  std::uint32_t ec_first_ = 0;
  std::uint32_t ec_end_ = 0;
  std::uint32_t ec_pool_ = 0;
};

// All beams of one grid in one representation.
class BeamStore {
 public:
  virtual ~BeamStore() = default;
  [[nodiscard]] virtual std::size_t beam_count() const = 0;
  // Returns the reading's ROI mass (DenseBeam::Update).
  virtual double Update(std::size_t beam, std::size_t outcome) = 0;
  // Applies updates[k] = (beam, outcome) in order, prefetching a few updates ahead so that a
  // frame's beams stream through memory instead of waiting on each one; roi_masses (if not
  // null) gets each update's ROI mass.
  struct BeamOutcome {
    std::uint32_t beam;
    std::uint32_t outcome;
  };
  virtual void UpdateMany(const BeamOutcome* updates, std::size_t count, double* roi_masses) = 0;
  virtual void Weights(std::size_t beam, std::vector<double>* weights) const = 0;
  virtual void TailMasses(std::size_t beam, const std::uint32_t* cells, std::size_t count,
                          double* out) const = 0;
  virtual void TailSpan(std::size_t beam, std::uint32_t first, std::uint32_t last,
                        std::vector<double>* out, double* total) const = 0;
  [[nodiscard]] virtual std::uint32_t TailDropCell(std::size_t beam, std::uint32_t from,
                                                   double fraction) const = 0;
  [[nodiscard]] virtual BeamProfileCells Profile(std::size_t beam, std::uint32_t from,
                                                 double tail_fraction, double free_ratio) const = 0;
  [[nodiscard]] virtual bool Touched(std::size_t beam) const = 0;
  virtual void Reset() = 0;
  virtual void ResetBeam(std::size_t beam) = 0;  // back to the prior
  [[nodiscard]] virtual std::size_t MemoryBytes() const = 0;  // beams only, not the context
};

[[nodiscard]] std::unique_ptr<BeamStore> MakeBeamStore(BeamRepresentation representation,
                                                       std::shared_ptr<const BeamContext> context,
                                                       std::size_t beam_count);

}  // namespace fusion
