// Forward sensor models p(r | B_i), i = 1..N+1, in ONE discrete form (docs/forward-model.md).
//
// Cells: cell i (0-based here, the paper's B_{i+1}) covers [i delta, (i+1) delta) with
// delta = cell_size; ||B|| is its centre (i + 1/2) delta. Index N stands for B_{N+1}.
// Outcomes: Omega = D u {beyond}. D = K bins of width delta over [0, K delta], K =
// ceil(r_limit / delta); bin k has centre (k + 1/2) delta. Outcome index K is `beyond`: a
// range reading r > r_limit or a point explicitly marked beyond range.
//
// Paper 3D model (Algorithm III.1), mu_i = q_mu(||B_i||), sigma_i = q_sigma(||B_i||),
// r_limit = q_mu(||B_N||) + Delta q_sigma(||B_N||), eps_bin = eps / (K + 1):
//   blind cell (||B_i|| < r_min):   0 for every outcome;
//   visible cell, bin k:            (1 - eps) * integral of Normal(r; mu_i, sigma_i) over
//                                   bin k clipped to the ROI [mu_i -+ Delta sigma_i], if bin k
//                                   overlaps the ROI, else eps_bin. For delta << sigma this is
//                                   (1 - eps) Normal(r_k; mu_i, sigma_i) delta; unlike that
//                                   midpoint form it sums to (1 - eps) erf(Delta / sqrt 2)
//                                   over D at ANY cell size (never above 1, never ~0);
//   visible cell, beyond:           eps_bin (Eq. 12 up to a floor: an exact 0 would make
//                                   B_{N+1} absorbing under the multiplicative Eq. 11);
//   B_{N+1}, bin k:                 eps / K (total over D = eps, Eq. 13);
//   B_{N+1}, beyond:                1 - eps (Eq. 14).
// Classic beam model (Probabilistic Robotics 6.3) on the same outcome space with
// r_limit = r_max (z_max_range): hit = normal around ||B_i|| truncated to [0, K delta],
// short = lambda e^{-lambda r} on [0, ||B_i||] normalised, rand = uniform over D, max = z_max
// on `beyond`; for B_{N+1} the hit mass also goes to `beyond` and short spans [0, K delta].
// Bin masses are exact integrals of the continuous densities, so every pmf sums to 1.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <vector>

#include "fusion/core/beam_types.h"
#include "fusion/core/sensor.h"

namespace fusion {

// Normal density N(r; mu, sigma^2) (paper Eq. 15).
[[nodiscard]] double NormalDensity(double r, double mu, double sigma);

// Cells of a beam r_max_m long in cells of cell_size_m (BeamDiscretisation::cell_count, N):
// ceil(r_max / delta), guarded against rounding (a 1 m beam of 1/21 m cells has 21, not 22),
// at least 1. Both arguments finite and > 0, and r_max / delta within std::size_t.
[[nodiscard]] std::size_t CellsPerBeam(double r_max_m, double cell_size_m);

// The cell and outcome grid shared by a forward model and the beams it updates.
struct BeamDiscretisation {
  double cell_size_m = 0.0;            // delta
  std::size_t cell_count = 0;          // N = CellsPerBeam(r_max, delta)
  std::size_t first_visible_cell = 0;  // cells below are blind (||B_i|| < r_min)
  double r_limit_m = 0.0;              // ranges above are the outcome `beyond`
  std::size_t bin_count = 0;           // K = ceil(r_limit / delta); outcome K = beyond

  [[nodiscard]] double CellRange(std::size_t cell) const {  // ||B_i||
    return (static_cast<double>(cell) + 0.5) * cell_size_m;
  }
  [[nodiscard]] double BinCentre(std::size_t bin) const {
    return (static_cast<double>(bin) + 0.5) * cell_size_m;
  }
  [[nodiscard]] std::size_t beyond_outcome() const { return bin_count; }
  [[nodiscard]] std::size_t outcome_count() const { return bin_count + 1; }
  // Outcome of a reading: bin, beyond, or std::nullopt (missing, NaN, negative range).
  [[nodiscard]] std::optional<std::size_t> OutcomeOf(const Reading& reading) const;
};

// A contiguous cell range [begin, end).
struct CellSpan {
  std::size_t begin = 0;
  std::size_t end = 0;
  [[nodiscard]] bool empty() const { return end <= begin; }
};

class ForwardModel {
 public:
  virtual ~ForwardModel() = default;
  [[nodiscard]] const BeamDiscretisation& discretisation() const { return disc_; }
  // p(outcome | B_{cell+1}); cell in [0, N] (N = B_{N+1}), outcome in [0, K] (K = beyond).
  [[nodiscard]] virtual double Probability(std::size_t cell, std::size_t outcome) const = 0;
  // Sparse structure used by the unrolled-linked-list beams: every visible cell OUTSIDE
  // Roi(outcome) has p(outcome | B_i) == OutsideRoiProbability(outcome) > 0. A model without
  // such structure returns all visible cells as the ROI (and 1 as the reference value).
  [[nodiscard]] virtual CellSpan Roi(std::size_t outcome) const = 0;
  [[nodiscard]] virtual double OutsideRoiProbability(std::size_t outcome) const = 0;

 protected:
  BeamDiscretisation disc_;
};

// The paper's 3D model (Algorithm III.1) in the discrete form above.
class Paper3dModel final : public ForwardModel {
 public:
  Paper3dModel(const SensorSpec& spec, double cell_size_m);
  [[nodiscard]] double Probability(std::size_t cell, std::size_t outcome) const override;
  [[nodiscard]] CellSpan Roi(std::size_t outcome) const override;
  [[nodiscard]] double OutsideRoiProbability(std::size_t outcome) const override;

  [[nodiscard]] double mu(std::size_t cell) const { return mu_m_[cell]; }
  [[nodiscard]] double sigma(std::size_t cell) const { return sigma_m_[cell]; }
  [[nodiscard]] double eps_bin() const { return eps_bin_; }
  // True if bin k overlaps the cell's ROI [mu_i - Delta sigma_i, mu_i + Delta sigma_i].
  [[nodiscard]] bool InRoi(std::size_t cell, std::size_t bin) const;
  // Normal mass of bin k clipped to the cell's ROI (0 outside).
  [[nodiscard]] double RoiMass(std::size_t cell, std::size_t bin) const;

 private:
  double eps_ = 0.0;
  double delta_sigmas_ = 3.0;
  double eps_bin_ = 0.0;
  std::vector<double> mu_m_, sigma_m_, inv_sigma_;  // per cell
  std::vector<std::uint32_t> roi_begin_, roi_end_;  // per bin
};

class ClassicBeamModel final : public ForwardModel {
 public:
  ClassicBeamModel(const SensorSpec& spec, double cell_size_m);
  [[nodiscard]] double Probability(std::size_t cell, std::size_t outcome) const override;
  [[nodiscard]] CellSpan Roi(std::size_t outcome) const override;
  [[nodiscard]] double OutsideRoiProbability(std::size_t outcome) const override { return 1.0; }

 private:
  ClassicBeamParams p_;             // weights normalised to sum 1
  std::vector<double> hit_norm_;    // per cell: 1 / (Phi(K delta) - Phi(0)) around ||B_i||
  std::vector<double> short_norm_;  // per cell: 1 / (1 - e^{-lambda ||B_i||})
};

// Builds the model named by spec.model. Throws std::invalid_argument for an invalid spec
// (ValidateSensorSpec) or cell size.
[[nodiscard]] std::unique_ptr<ForwardModel> MakeForwardModel(const SensorSpec& spec,
                                                             double cell_size_m);

}  // namespace fusion
