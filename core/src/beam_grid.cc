// The per-sensor beam grid (the tessellation is in beam_tessellation.cc).
#include "fusion/core/beam_grid.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>
#include <utility>

#include "fusion/core/beam.h"
#include "fusion/core/forward_model.h"

namespace fusion {

struct BeamGrid::Impl {
  Impl(const SensorSpec& s, const BeamGridOptions& o)
      : Impl(s, o, std::make_shared<const BeamContext>(s, o)) {}
  Impl(const SensorSpec& s, const BeamGridOptions& o, std::shared_ptr<const BeamContext> c)
      : spec(s),
        options(o),
        tessellation(s),
        context(std::move(c)),
        store(MakeBeamStore(o.representation, context, tessellation.beam_count())) {}

  SensorSpec spec;
  BeamGridOptions options;
  BeamTessellation tessellation;
  std::shared_ptr<const BeamContext> context;
  std::unique_ptr<BeamStore> store;
  std::vector<BeamStore::BeamOutcome> scratch;  // reused by Integrate / UpdateEachBeam
  // Change detection (BeamGridOptions::change_run), per beam: whether a reading has found the
  // beam's p(B) holding it (ROI mass >= kConfidentMass) since the beam (re)started, the
  // surprising clouds in a row (up to 100, in the low bits) and a reading of each of them.
  static constexpr std::uint8_t kConfident = 0x80;
  static constexpr double kConfidentMass = 0.5;
  std::vector<std::uint8_t> state;
  std::vector<std::uint32_t> held;  // change_run - 1 per beam
  std::vector<double> masses;       // each update's ROI mass (BeamStore::UpdateMany)
  // One cloud's readings of each beam it touched (reset after the cloud).
  struct Tally {
    std::uint32_t readings = 0;
    std::uint32_t surprising = 0;
    std::uint32_t first_surprising = 0;  // its outcome
    bool believes = false;               // some reading found kConfidentMass
  };
  std::vector<Tally> tally;
  std::vector<std::uint32_t> touched;    // beams with a tally
  std::vector<std::uint8_t> restarting;  // beams restarted after this cloud

  // Applies one cloud's updates in order. With change detection on, each reading is judged by
  // its ROI mass under the posterior it met (the update's own by-product), and each beam by
  // its readings in the cloud: a cloud is one observation, so a beam whose footprint holds two
  // depths (several pixels per beam) is not mistaken for a change. A confident beam is
  // surprised by a cloud when more than half of its readings in it were surprising; change_run
  // surprised clouds in a row restart it at its prior after the cloud, and it takes a reading
  // of each earlier cloud of the run and every reading of this one again. Any other cloud
  // with readings of the beam ends its run. Every reading is applied (the model's outlier
  // floor accounts for the odd surprising one).
  void Apply(const std::vector<BeamStore::BeamOutcome>& todo, IntegrationStats* stats);
  // The verdict on one beam's tally; true if the beam restarts.
  bool Judge(std::uint32_t beam, const Tally& t);

  void CheckBeam(std::size_t beam) const {
    if (beam >= store->beam_count()) throw std::out_of_range("beam index out of range");
  }
};

void BeamGrid::Impl::Apply(const std::vector<BeamStore::BeamOutcome>& todo,
                           IntegrationStats* stats) {
  const std::uint32_t limit = options.change_run;
  if (limit == 0) {
    store->UpdateMany(todo.data(), todo.size(), nullptr);
    return;
  }
  if (state.empty()) {
    state.assign(store->beam_count(), 0);
    held.assign(store->beam_count() * (limit - 1), 0);
    tally.assign(store->beam_count(), Tally{});
    restarting.assign(store->beam_count(), 0);
  }
  masses.resize(todo.size());
  store->UpdateMany(todo.data(), todo.size(), masses.data());
  for (std::size_t k = 0; k < todo.size(); ++k) {
    const BeamStore::BeamOutcome& u = todo[k];
    Tally& t = tally[u.beam];
    if (t.readings == 0) touched.push_back(u.beam);
    ++t.readings;
    const double mass = masses[k];
    t.believes |= mass >= kConfidentMass;
    if ((state[u.beam] & kConfident) != 0 && mass >= 0.0 && mass < options.change_min_mass &&
        t.surprising++ == 0) {
      t.first_surprising = u.outcome;
    }
  }
  std::size_t restarts = 0;
  for (const std::uint32_t beam : touched) {
    if (Judge(beam, tally[beam])) {
      restarting[beam] = 1;
      ++restarts;
      store->ResetBeam(beam);  // and the run's earlier clouds again
      bool believes = false;
      for (std::uint32_t k = 0; k + 1 < limit; ++k) {
        believes |= store->Update(beam, held[beam * (limit - 1) + k]) >= kConfidentMass;
      }
      state[beam] = believes ? kConfident : 0;
    }
    tally[beam] = Tally{};
  }
  touched.clear();
  if (restarts == 0) return;
  stats->changes_detected += restarts;
  for (const BeamStore::BeamOutcome& u : todo) {  // this cloud again, in order
    if (restarting[u.beam] == 0) continue;
    if (store->Update(u.beam, u.outcome) >= kConfidentMass) state[u.beam] = kConfident;
  }
  for (const BeamStore::BeamOutcome& u : todo) restarting[u.beam] = 0;
}

bool BeamGrid::Impl::Judge(std::uint32_t beam, const Tally& t) {
  const std::uint32_t limit = options.change_run;
  std::uint8_t& s = state[beam];
  const bool confident = (s & kConfident) != 0;
  if (!confident || 2u * t.surprising <= t.readings) {  // expected: the run ends
    s = (confident || t.believes) ? kConfident : 0;
    return false;
  }
  const std::uint32_t run = s & ~kConfident;
  if (run + 1 < limit) {  // outliers, or the start of a change
    held[beam * (limit - 1) + run] = t.first_surprising;
    s = static_cast<std::uint8_t>(kConfident | (run + 1));
    return false;
  }
  return true;  // the world changed along this beam
}

BeamGrid::BeamGrid(const SensorSpec& spec, const BeamGridOptions& options)
    : impl_(std::make_unique<Impl>(spec, options)) {}
BeamGrid::BeamGrid(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}

std::unique_ptr<BeamGrid> BeamGrid::EmptyCopy() const {
  return std::unique_ptr<BeamGrid>(
      new BeamGrid(std::make_unique<Impl>(impl_->spec, impl_->options, impl_->context)));
}

BeamGrid::~BeamGrid() = default;
BeamGrid::BeamGrid(BeamGrid&&) noexcept = default;
BeamGrid& BeamGrid::operator=(BeamGrid&&) noexcept = default;

const SensorSpec& BeamGrid::spec() const { return impl_->spec; }
const BeamGridOptions& BeamGrid::options() const { return impl_->options; }
const BeamTessellation& BeamGrid::tessellation() const { return impl_->tessellation; }
std::size_t BeamGrid::cells_per_beam() const { return impl_->context->cell_count(); }
std::size_t BeamGrid::beam_count() const { return impl_->store->beam_count(); }
double BeamGrid::prior_cell_occupancy() const { return impl_->context->prior(); }
std::size_t BeamGrid::first_visible_cell() const {
  return impl_->context->disc().first_visible_cell;
}
double BeamGrid::r_limit_m() const { return impl_->context->disc().r_limit_m; }

IntegrationStats BeamGrid::Integrate(const float* points_xyz, std::size_t point_count,
                                     const std::vector<std::uint8_t>& beyond_range) {
  IntegrationStats stats;
  if (point_count == 0) return stats;
  if (points_xyz == nullptr) throw std::invalid_argument("points_xyz is null");
  if (!beyond_range.empty() && beyond_range.size() != point_count) {
    throw std::invalid_argument("beyond_range has " + std::to_string(beyond_range.size()) +
                                " flags for " + std::to_string(point_count) + " points");
  }
  const BeamDiscretisation& disc = impl_->context->disc();
  std::vector<BeamStore::BeamOutcome>& todo = impl_->scratch;
  todo.clear();
  for (std::size_t k = 0; k < point_count; ++k) {
    const float* p = points_xyz + 3 * k;
    const bool nan_x = std::isnan(p[0]);
    const bool nan_y = std::isnan(p[1]);
    const bool nan_z = std::isnan(p[2]);
    if (nan_x && nan_y && nan_z) {
      ++stats.missing;
      continue;
    }
    if (!std::isfinite(p[0]) || !std::isfinite(p[1]) || !std::isfinite(p[2])) {
      ++stats.rejected_nonfinite;
      continue;
    }
    const Eigen::Vector3d point(p[0], p[1], p[2]);
    if (point.x() == 0.0 && point.y() == 0.0 && point.z() == 0.0) {
      ++stats.missing;
      continue;
    }
    const std::optional<std::size_t> beam = impl_->tessellation.BeamOf(point);
    if (!beam) {
      ++stats.rejected_outside_fov;
      continue;
    }
    Reading reading;
    if (!beyond_range.empty() && beyond_range[k] != 0) {
      reading.kind = Reading::Kind::kBeyondRange;
    } else {
      reading.kind = Reading::Kind::kRange;
      reading.range_m = point.norm();
    }
    const std::optional<std::size_t> outcome = disc.OutcomeOf(reading);
    if (!outcome) {  // unreachable for finite non-zero points; counted, never applied
      ++stats.rejected_nonfinite;
      continue;
    }
    todo.push_back({static_cast<std::uint32_t>(*beam), static_cast<std::uint32_t>(*outcome)});
    if (*outcome == disc.beyond_outcome()) {
      ++stats.beyond_range;
    } else {
      ++stats.updated;
    }
  }
  impl_->Apply(todo, &stats);
  return stats;
}

IntegrationStats BeamGrid::UpdateEachBeam(const std::vector<Reading>& readings) {
  if (readings.size() != beam_count()) {
    throw std::invalid_argument("UpdateEachBeam needs one reading per beam (" +
                                std::to_string(beam_count()) + "), got " +
                                std::to_string(readings.size()));
  }
  IntegrationStats stats;
  const BeamDiscretisation& disc = impl_->context->disc();
  std::vector<BeamStore::BeamOutcome>& todo = impl_->scratch;
  todo.clear();
  for (std::size_t b = 0; b < readings.size(); ++b) {
    const std::optional<std::size_t> outcome = disc.OutcomeOf(readings[b]);
    if (!outcome) {
      ++stats.missing;
      continue;
    }
    todo.push_back({static_cast<std::uint32_t>(b), static_cast<std::uint32_t>(*outcome)});
    if (*outcome == disc.beyond_outcome()) {
      ++stats.beyond_range;
    } else {
      ++stats.updated;
    }
  }
  impl_->Apply(todo, &stats);
  return stats;
}

bool BeamGrid::Update(std::size_t beam, const Reading& reading) {
  impl_->CheckBeam(beam);
  const std::optional<std::size_t> outcome = impl_->context->disc().OutcomeOf(reading);
  if (!outcome) return false;
  impl_->store->Update(beam, *outcome);
  return true;
}

std::vector<double> BeamGrid::FirstHitProbabilities(std::size_t beam) const {
  impl_->CheckBeam(beam);
  std::vector<double> w;
  impl_->store->Weights(beam, &w);
  double total = 0.0;
  for (std::size_t i = w.size(); i-- > 0;) total += w[i];
  const double eta = 1.0 / total;
  for (double& v : w) v *= eta;
  return w;
}

std::vector<double> BeamGrid::CellProbabilities(std::size_t beam) const {
  impl_->CheckBeam(beam);
  std::vector<double> w;
  impl_->store->Weights(beam, &w);
  return CellsFromFirstHit(w, impl_->context->prior());
}

void BeamGrid::IntervalOccupancy(std::size_t beam, const std::vector<double>& boundaries_m,
                                 std::vector<double>* out) const {
  impl_->CheckBeam(beam);
  out->clear();
  if (boundaries_m.size() < 2) return;
  // cells[0] = 0 (the whole beam's mass), then one cell per boundary; one TailMasses walk
  // answers both. Scratch per thread: renders call this from several threads.
  thread_local std::vector<std::uint32_t> cells;
  thread_local std::vector<double> tails;
  cells.resize(boundaries_m.size() + 1);
  cells[0] = 0;
  std::uint32_t previous = 0;
  for (std::size_t j = 0; j < boundaries_m.size(); ++j) {
    const std::uint32_t ci = std::max(previous, CellOf(boundaries_m[j]));  // ascending
    cells[j + 1] = ci;
    previous = ci;
  }
  tails.resize(cells.size());
  TailMasses(beam, cells.data(), cells.size(), tails.data());
  const double* tail = tails.data() + 1;
  out->resize(boundaries_m.size() - 1);
  for (std::size_t j = 0; j + 1 < boundaries_m.size(); ++j) {
    (*out)[j] =
        IntervalOccupancyOfCells(tail[j], tail[j + 1], tails[0], cells[j + 2] - cells[j + 1]);
  }
}

void BeamGrid::TailMasses(std::size_t beam, const std::uint32_t* cells, std::size_t count,
                          double* out) const {
  impl_->CheckBeam(beam);
  const auto n = static_cast<std::uint32_t>(cells_per_beam());
  for (std::size_t j = 0; j < count; ++j) {
    if (cells[j] > n || (j > 0 && cells[j] < cells[j - 1])) {
      throw std::invalid_argument("TailMasses needs ascending cells of at most N");
    }
  }
  impl_->store->TailMasses(beam, cells, count, out);
}

std::uint32_t BeamGrid::CellOf(double range_m) const {
  return CellOfRange(range_m, impl_->options.cell_size_m, cells_per_beam());
}

double BeamGrid::IntervalOccupancyOfCells(double tail_a, double tail_b, double total,
                                          std::uint32_t cells) const {
  if (tail_a > kNoInformationTail * total) {
    // Telescoping Eq. 8: prod_{i in [a, b)} (1 - p(m_i)) = S_b / S_a.
    return std::clamp(1.0 - tail_b / tail_a, 0.0, 1.0);
  }
  return PriorOccupancy(static_cast<double>(cells) * impl_->options.cell_size_m);
}

void BeamGrid::TailMassSpan(std::size_t beam, std::uint32_t first, std::uint32_t last,
                            std::vector<double>* tails, double* total) const {
  impl_->CheckBeam(beam);
  const auto n = static_cast<std::uint32_t>(cells_per_beam());
  first = std::min(first, n);
  last = std::min(std::max(last, first), n);
  impl_->store->TailSpan(beam, first, last, tails, total);
}

double BeamGrid::InformationEndM(std::size_t beam, double from_m, double fraction) const {
  impl_->CheckBeam(beam);
  const std::size_t n = cells_per_beam();
  const double cell = impl_->options.cell_size_m;
  double from = std::round(from_m / cell);
  if (!(from >= 0.0)) from = 0.0;
  from = std::min(from, static_cast<double>(n));
  const std::uint32_t c =
      impl_->store->TailDropCell(beam, static_cast<std::uint32_t>(from), fraction);
  if (c > n) return std::numeric_limits<double>::infinity();
  return static_cast<double>(c) * cell;
}

BeamProfile BeamGrid::Profile(std::size_t beam, double from_m, double tail_fraction,
                              double free_ratio) const {
  impl_->CheckBeam(beam);
  const std::size_t n = cells_per_beam();
  const double cell = impl_->options.cell_size_m;
  double from = std::round(from_m / cell);
  if (!(from >= 0.0)) from = 0.0;
  from = std::min(from, static_cast<double>(n));
  const auto start = static_cast<std::uint32_t>(from);
  const BeamProfileCells cells = impl_->store->Profile(beam, start, tail_fraction, free_ratio);
  constexpr double kInf = std::numeric_limits<double>::infinity();
  BeamProfile out;
  out.mass_begin_m = cells.mass_begin > n ? kInf : cells.mass_begin * cell;
  out.info_end_m = cells.info_end > n ? kInf : cells.info_end * cell;
  out.median_m = cells.median > n ? kInf : cells.median * cell;
  const std::size_t end = std::min<std::size_t>(cells.mass_begin, n);
  if (end <= start) {
    out.free_log_odds = -kInf;
  } else {
    const double prior_hazard = -std::log1p(-impl_->context->prior()) * double(end - start);
    out.free_log_odds = std::log(std::max(cells.free_hazard, 1e-300) / prior_hazard);
  }
  return out;
}

double BeamGrid::PriorOccupancy(double length_m) const {
  if (!(length_m > 0.0)) return 0.0;
  return -std::expm1(std::log1p(-impl_->context->prior()) * length_m / impl_->options.cell_size_m);
}

bool BeamGrid::Touched(std::size_t beam) const {
  impl_->CheckBeam(beam);
  return impl_->store->Touched(beam);
}

void BeamGrid::Reset() {
  impl_->store->Reset();
  // Nothing to contradict: a restarted grid (a recycled period's) holds no belief yet.
  std::fill(impl_->state.begin(), impl_->state.end(), std::uint8_t{0});
}

std::size_t BeamGrid::MemoryBytes() const {
  return sizeof(*this) + sizeof(Impl) + impl_->store->MemoryBytes() + impl_->context->MemoryBytes();
}

}  // namespace fusion
