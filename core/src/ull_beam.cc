// The paper's unrolled linked list of composite cells (Sec. IV-A): exploded composites keep
// per-cell weights in one pool, unexploded ones a closed-form geometric run.
#include <algorithm>
#include <cmath>
#include <cstring>

#include "beam_store_of.h"
#include "fusion/core/beam.h"

namespace fusion {
namespace {
// Two doubles (SSE2 on x86-64, NEON on arm64) for the ROI update's inner loop.
using V2 = double __attribute__((vector_size(16)));

// v[0] + ... + v[n - 1] in four independent sums (an EC's stretch: the add chain, not the
// loads, would set the pace).
double PoolSum(const double* v, std::size_t n) {
  double a = 0.0, b = 0.0, c = 0.0, d = 0.0;
  std::size_t t = 0;
  for (; t + 4 <= n; t += 4) {
    a += v[t];
    b += v[t + 1];
    c += v[t + 2];
    d += v[t + 3];
  }
  for (; t < n; ++t) a += v[t];
  return (a + b) + (c + d);
}

// Room for S at every composite's start and after the last (TailsAtComposites): on the stack
// for the usual short list, in a per-thread vector beyond (renders read beams from several
// threads; Profile and TailMasses never hold one while calling the other).
class TailBuffer {
 public:
  double* For(std::size_t composites) {
    if (composites + 1 <= kLocal) return local_;
    thread_local std::vector<double> heap;
    heap.resize(composites + 1);
    return heap.data();
  }

 private:
  static constexpr std::size_t kLocal = 33;
  double local_[kLocal];
};
}  // namespace

UllBeam::UllBeam(const BeamContext& ctx) { Reset(ctx); }

void UllBeam::Reset(const BeamContext& ctx) {
  // Keeps the vectors' memory: a recycled grid's beams fill up again much as before.
  list_.clear();
  pool_.clear();
  const std::size_t n = ctx.cell_count();
  const std::size_t visible = std::min(ctx.disc().first_visible_cell, n);
  // Split at the r_min boundary: blind and visible cells see different constant models.
  if (visible > 0) {
    list_.push_back({0, static_cast<std::uint32_t>(visible), 0, 0, ctx.prior()});
  }
  if (visible < n) {
    list_.push_back({static_cast<std::uint32_t>(visible), static_cast<std::uint32_t>(n - visible),
                     0, 0, ctx.prior() * ctx.RhoPow(visible)});
  }
  w_all_free_ = ctx.RhoPow(n);
  ec_first_ = ec_end_ = ec_pool_ = 0;
  total_ = ExactTotal(ctx);
  total_error_ = kSumError * total_;
  touched_ = false;
}

std::size_t UllBeam::Find(std::size_t cell) const {
  auto it = std::upper_bound(list_.begin(), list_.end(), cell,
                             [](std::size_t value, const Composite& c) { return value < c.first; });
  return static_cast<std::size_t>(it - list_.begin()) - 1;
}

double UllBeam::CompositeSum(const BeamContext& ctx, const Composite& c) const {
  if (c.exploded == 0) return c.w_first * ctx.GeomSum(c.count);
  double s = 0.0;
  for (std::uint32_t t = c.count; t-- > 0;) s += pool_[c.pool_begin + t];
  return s;
}

std::size_t UllBeam::Explode(const BeamContext& ctx, std::size_t begin, std::size_t end) {
  const std::size_t hit = Find(begin);
  if (list_[hit].exploded != 0 && std::size_t{list_[hit].first} + list_[hit].count >= end) {
    return hit;  // steady state: the ROI already lies in one EC
  }
  std::size_t pos = begin;
  while (pos < end) {
    std::size_t idx = Find(pos);
    const Composite c = list_[idx];
    const std::size_t c_end = std::size_t{c.first} + c.count;
    if (c.exploded != 0) {
      pos = c_end;
      continue;
    }
    // Split the UEC into [c.first, a) UEC, [a, b) EC, [b, c_end) UEC.
    const std::size_t a = pos;
    const std::size_t b = std::min(c_end, end);
    const std::uint32_t len = static_cast<std::uint32_t>(b - a);
    const std::uint32_t at = c.pool_begin;
    pool_.insert(pool_.begin() + at, len, 0.0);
    for (std::uint32_t t = 0; t < len; ++t) {
      pool_[at + t] = c.w_first * ctx.RhoPow(a + t - c.first);
    }
    for (std::size_t k = idx + 1; k < list_.size(); ++k) list_[k].pool_begin += len;
    Composite pieces[3];
    std::size_t count = 0;
    if (a > c.first) {
      pieces[count++] = {c.first, static_cast<std::uint32_t>(a - c.first), at, 0, c.w_first};
    }
    const std::size_t ec = idx + count;
    pieces[count++] = {static_cast<std::uint32_t>(a), len, at, 1, 0.0};
    if (b < c_end) {
      pieces[count++] = {static_cast<std::uint32_t>(b), static_cast<std::uint32_t>(c_end - b),
                         at + len, 0, c.w_first * ctx.RhoPow(b - c.first)};
    }
    list_[idx] = pieces[0];
    list_.insert(list_.begin() + static_cast<std::ptrdiff_t>(idx) + 1, pieces + 1, pieces + count);
    // Merge with EC neighbours (their pool values are adjacent: the pool is in list order).
    std::size_t e = ec;
    if (e + 1 < list_.size() && list_[e + 1].exploded != 0) {
      list_[e].count += list_[e + 1].count;
      list_.erase(list_.begin() + static_cast<std::ptrdiff_t>(e) + 1);
    }
    if (e > 0 && list_[e - 1].exploded != 0) {
      list_[e - 1].count += list_[e].count;
      list_.erase(list_.begin() + static_cast<std::ptrdiff_t>(e));
    }
    pos = b;
  }
  return Find(begin);
}

double UllBeam::Update(const BeamContext& ctx, std::size_t outcome) {
  if (!touched_) {
    // Blind cells have p(r | B_i) = 0 for every outcome: the first reading zeroes them.
    const std::size_t visible = ctx.disc().first_visible_cell;
    for (Composite& c : list_) {
      if (c.first >= visible) break;
      const double sum = CompositeSum(ctx, c);
      total_error_ += kSumError * sum;
      total_ -= sum;
      c.w_first = 0.0;
      for (std::uint32_t t = 0; c.exploded != 0 && t < c.count; ++t) pool_[c.pool_begin + t] = 0;
    }
    touched_ = true;
  }
  double delta = 0.0;
  double roi_sum = -1.0;  // the ROI's weights before the update; -1: no ROI
  const BeamContext::RoiFactors roi = ctx.Roi(outcome);
  if (roi.end > roi.begin) {
    if (!(roi.begin >= ec_first_ && roi.end <= ec_end_)) {
      const Composite& c = list_[Explode(ctx, roi.begin, roi.end)];
      ec_first_ = c.first;
      ec_end_ = c.first + c.count;
      ec_pool_ = c.pool_begin;
    }
    double* v = pool_.data() + ec_pool_ + (roi.begin - ec_first_);
    const std::size_t len = roi.end - roi.begin;
    if (roi.factors != nullptr) {
      // delta = sum_t v_t (f_t - 1), four independent sums (two 2-lane vectors) to break the
      // add chain; the pool and the factor table never overlap.
      const double* f = roi.factors;
      V2 d01 = {0.0, 0.0};
      V2 d23 = {0.0, 0.0};
      V2 s01 = {0.0, 0.0};
      V2 s23 = {0.0, 0.0};
      const V2 one = {1.0, 1.0};
      std::size_t t = 0;
      for (; t + 4 <= len; t += 4) {
        V2 a, b, fa, fb;
        std::memcpy(&a, v + t, sizeof a);
        std::memcpy(&b, v + t + 2, sizeof b);
        std::memcpy(&fa, f + t, sizeof fa);
        std::memcpy(&fb, f + t + 2, sizeof fb);
        s01 += a;
        s23 += b;
        d01 += a * (fa - one);
        d23 += b * (fb - one);
        a *= fa;
        b *= fb;
        std::memcpy(v + t, &a, sizeof a);
        std::memcpy(v + t + 2, &b, sizeof b);
      }
      double tail = 0.0;
      double tail_sum = 0.0;
      for (; t < len; ++t) {
        const double old = v[t];
        v[t] = old * f[t];
        tail += old * (f[t] - 1.0);
        tail_sum += old;
      }
      delta = ((d01[0] + tail) + d01[1]) + (d23[0] + d23[1]);
      roi_sum = ((s01[0] + tail_sum) + s01[1]) + (s23[0] + s23[1]);
    } else {
      roi_sum = 0.0;
      for (std::size_t t = 0; t < len; ++t) {
        const double old = v[t];
        v[t] = old * ctx.Factor(roi.begin + t, outcome);
        delta += v[t] - old;
        roi_sum += old;
      }
    }
  }
  if (outcome == ctx.disc().beyond_outcome()) roi_sum = w_all_free_;  // B_{N+1} alone
  const double mass = roi_sum < 0.0 ? -1.0 : roi_sum / total_;
  const double g = ctx.AllFreeFactor(outcome);
  const double old_free = w_all_free_;
  w_all_free_ *= g;
  delta += w_all_free_ - old_free;
  // The sums of the update err by at most kUpdateError of the weights they add (every term
  // |v (f - 1)| is at most a weight before plus one after): the bound grows with the weights
  // before and after, which matters where an update takes away nearly all of the total.
  total_error_ += kUpdateError * (total_ + std::abs(total_ + delta));
  total_ += delta;
  if (!(total_ >= kLowTotal && total_ <= kHighTotal)) {
    Renormalise(ctx);
  } else if (!(total_error_ <= kMaxTotalError * total_)) {
    Resum(ctx);
  }
  return mass;
}

double UllBeam::ExactTotal(const BeamContext& ctx) const {
  double exact = w_all_free_;
  for (const Composite& c : list_) exact += CompositeSum(ctx, c);
  return exact;
}

void UllBeam::Resum(const BeamContext& ctx) {
  const double exact = ExactTotal(ctx);
  total_ = exact;
  total_error_ = kSumError * exact;
  if (!(total_ >= kLowTotal && total_ <= kHighTotal)) Renormalise(ctx);
}

void UllBeam::Renormalise(const BeamContext& ctx) {
  const double exact = ExactTotal(ctx);
  if (!(exact > 0.0) || !std::isfinite(exact)) {  // impossible outcome: start afresh
    Reset(ctx);
    touched_ = true;
    return;
  }
  const double scale = 1.0 / exact;
  for (Composite& c : list_) c.w_first *= scale;
  for (double& v : pool_) v *= scale;
  w_all_free_ *= scale;
  total_ = 1.0;
  total_error_ = kSumError;
}

void UllBeam::Weights(const BeamContext& ctx, std::vector<double>* weights) const {
  const std::size_t n = ctx.cell_count();
  weights->resize(n + 1);
  for (const Composite& c : list_) {
    for (std::uint32_t t = 0; t < c.count; ++t) {
      (*weights)[c.first + t] =
          c.exploded != 0 ? pool_[c.pool_begin + t] : c.w_first * ctx.RhoPow(t);
    }
  }
  (*weights)[n] = w_all_free_;
}

std::uint32_t UllBeam::TailDropCell(const BeamContext& ctx, std::uint32_t from,
                                    double fraction) const {
  const std::size_t n = ctx.cell_count();
  const auto none = static_cast<std::uint32_t>(n + 1);
  const std::uint32_t start = std::min<std::uint32_t>(from, static_cast<std::uint32_t>(n));
  double s_start = 0.0;
  TailMasses(ctx, &start, 1, &s_start);
  const double threshold = fraction * s_start;
  double acc = w_all_free_;  // S(N)
  if (acc >= threshold) return none;
  for (std::size_t k = list_.size(); k-- > 0;) {
    const Composite& c = list_[k];
    const std::size_t c_end = std::size_t{c.first} + c.count;
    if (c.exploded == 0) {
      const double sum = c.w_first * ctx.GeomSum(c.count);
      if (acc + sum < threshold) {
        acc += sum;
        continue;
      }
      // S(x) = acc + w_first rho^(x - first) GeomSum(c_end - x) falls with x: the largest x
      // with S(x) >= threshold, by bisection ([lo] holds, (hi] does not).
      std::size_t lo = c.first, hi = c_end;
      while (hi - lo > 1) {
        const std::size_t mid = lo + (hi - lo) / 2;
        const double s_mid = acc + c.w_first * ctx.RhoPow(mid - c.first) * ctx.GeomSum(c_end - mid);
        (s_mid >= threshold ? lo : hi) = mid;
      }
      return static_cast<std::uint32_t>(std::max<std::size_t>(lo + 1, start + 1));
    }
    for (std::size_t t = c.count; t-- > 0;) {
      acc += pool_[c.pool_begin + t];
      if (acc >= threshold) {
        return static_cast<std::uint32_t>(std::max<std::size_t>(c.first + t + 1, start + 1));
      }
    }
  }
  return static_cast<std::uint32_t>(start + 1);  // fraction >= 1
}

// Profile's steps are inline: called from Profile alone, and a call each costs ~5 % of it.
inline void UllBeam::TailsAtComposites(const BeamContext& ctx, double* s_at) const {
  // The usual beam has one EC: its sum is the running total less the closed-form rest, unless
  // that would cancel (a small EC next to large runs), so the profile costs a few cells of it
  // only.
  double closed = w_all_free_;
  std::size_t ecs = 0;
  for (const Composite& c : list_) {
    if (c.exploded == 0) {
      closed += c.w_first * ctx.GeomSum(c.count);
    } else {
      ++ecs;
    }
  }
  const double derived_ec = total_ - closed;
  const bool derive = ecs == 1 && total_error_ <= kDerivedError * derived_ec;
  double acc = w_all_free_;
  s_at[list_.size()] = acc;
  for (std::size_t k = list_.size(); k-- > 0;) {
    const Composite& c = list_[k];
    s_at[k] = acc += (c.exploded != 0 && derive) ? derived_ec : CompositeSum(ctx, c);
  }
}

inline UllBeam::FreeZoneTails UllBeam::ScanFreeZone(const BeamContext& ctx, const double* s_at,
                                                    std::size_t start, double free_ratio,
                                                    BeamProfileCells* out) const {
  const std::size_t n = ctx.cell_count();
  const double no_information = kNoInformationTail * s_at[0];
  out->mass_begin = static_cast<std::uint32_t>(n + 1);
  const double ratio = free_ratio * ctx.prior();
  FreeZoneTails tails{-1.0, w_all_free_};  // S(start) unknown yet; S at the end if none found
  for (std::size_t k = 0; k < list_.size(); ++k) {
    const Composite& c = list_[k];
    const std::size_t c_end = std::size_t{c.first} + c.count;
    if (c_end <= start) continue;
    const std::size_t j0 = std::max<std::size_t>(c.first, start);
    if (c.exploded == 0) {
      const double w = c.w_first * ctx.RhoPow(j0 - c.first);
      const double s = s_at[k + 1] + w * ctx.GeomSum(c_end - j0);
      if (tails.s_start < 0.0) tails.s_start = s;
      if (s <= no_information || w > ratio * s) {
        out->mass_begin = static_cast<std::uint32_t>(j0);
        tails.s_end = s;
        return tails;
      }
      continue;  // below p0 the run's p(m) only falls: no cell of it reaches the ratio
    }
    double s = s_at[k];
    for (std::size_t t = 0; t < j0 - c.first; ++t) s -= pool_[c.pool_begin + t];
    for (std::size_t j = j0; j < c_end; ++j) {
      if (tails.s_start < 0.0) tails.s_start = s;
      const double w = pool_[c.pool_begin + (j - c.first)];
      if (s <= no_information || w > ratio * s) {
        out->mass_begin = static_cast<std::uint32_t>(j);
        tails.s_end = s;
        return tails;
      }
      s -= w;
    }
  }
  return tails;
}

inline std::size_t UllBeam::WalkDown(const Composite& c, std::size_t t, double threshold,
                                     double* tail) const {
  while (t > 0) {
    *tail += pool_[c.pool_begin + --t];
    if (*tail >= threshold) break;
  }
  return t;
}

inline std::uint32_t UllBeam::FirstCellBelow(const BeamContext& ctx, const double* s_at,
                                             std::size_t start, double s_start,
                                             double fraction) const {
  const std::size_t n = ctx.cell_count();
  const double threshold = fraction * s_start;
  if (w_all_free_ >= threshold) return static_cast<std::uint32_t>(n + 1);
  std::size_t k = list_.size();
  while (k > 0 && s_at[k - 1] < threshold) --k;
  std::size_t cell = start + 1;  // S(start) itself is below: fraction > 1
  if (k > 0) {
    const Composite& c = list_[k - 1];
    const std::size_t c_end = std::size_t{c.first} + c.count;
    if (c.exploded == 0) {
      // S(x) = s_at[k] + w_first rho^(x - first) GeomSum(c_end - x) falls with x: the largest
      // x with S(x) >= threshold, by bisection ([lo] holds, (hi] does not).
      std::size_t lo = c.first, hi = c_end;
      while (hi - lo > 1) {
        const std::size_t mid = lo + (hi - lo) / 2;
        const double s_mid =
            s_at[k] + c.w_first * ctx.RhoPow(mid - c.first) * ctx.GeomSum(c_end - mid);
        (s_mid >= threshold ? lo : hi) = mid;
      }
      cell = lo + 1;
    } else {
      double tail = s_at[k];
      cell = c.first + WalkDown(c, c.count, threshold, &tail) + 1;
    }
  }
  return static_cast<std::uint32_t>(std::max(cell, start + 1));
}

inline void UllBeam::InfoEndAndMedian(const BeamContext& ctx, const double* s_at, std::size_t start,
                                      double s_start, double tail_fraction,
                                      BeamProfileCells* out) const {
  const double info = tail_fraction * s_start, half = 0.5 * s_start;
  // The composite each threshold falls in (s_at does not rise with k): as FirstCellBelow finds it.
  std::size_t k_info = list_.size();
  while (k_info > 0 && s_at[k_info - 1] < info) --k_info;
  std::size_t k_half = k_info;
  while (k_half > 0 && s_at[k_half - 1] < half) --k_half;
  if (!(info < half) || w_all_free_ >= info || k_info != k_half || k_info == 0 ||
      list_[k_info - 1].exploded == 0) {
    out->info_end = FirstCellBelow(ctx, s_at, start, s_start, tail_fraction);
    out->median = FirstCellBelow(ctx, s_at, start, s_start, 0.5);
    return;
  }
  // Both in one exploded composite: FirstCellBelow's walk down from its end, which passes the
  // lower threshold first, then on to the higher one (the same sums in the same order).
  const Composite& c = list_[k_info - 1];
  double tail = s_at[k_info];
  const std::size_t t_info = WalkDown(c, c.count, info, &tail);
  const std::size_t t = tail >= half ? t_info : WalkDown(c, t_info, half, &tail);
  out->info_end = static_cast<std::uint32_t>(std::max(c.first + t_info + 1, start + 1));
  out->median = static_cast<std::uint32_t>(std::max(c.first + t + 1, start + 1));
}

BeamProfileCells UllBeam::Profile(const BeamContext& ctx, std::uint32_t from, double tail_fraction,
                                  double free_ratio) const {
  const std::size_t n = ctx.cell_count();
  const std::size_t start = std::min<std::size_t>(from, n);
  // S at the start of every composite (s_at[k]), and after the last one (B_{N+1} alone).
  TailBuffer buffer;
  double* s_at = buffer.For(list_.size());
  TailsAtComposites(ctx, s_at);
  BeamProfileCells out;
  FreeZoneTails zone = ScanFreeZone(ctx, s_at, start, free_ratio, &out);
  if (zone.s_start < 0.0) zone.s_start = w_all_free_;  // start == N
  out.free_hazard = zone.s_start > 0.0 && out.mass_begin > start
                        ? -std::log(std::max(zone.s_end, 0.0) / zone.s_start)
                        : 0.0;
  if (!std::isfinite(out.free_hazard)) out.free_hazard = 0.0;
  // Information end and median (TailDropCell): the composite where S falls below the
  // threshold, then the cell inside it.
  InfoEndAndMedian(ctx, s_at, start, zone.s_start, tail_fraction, &out);
  return out;
}

void UllBeam::TailMasses(const BeamContext& ctx, const std::uint32_t* cells, std::size_t count,
                         double* out) const {
  const std::size_t n = ctx.cell_count();
  // S at every composite's start (the usual beam's one EC derived, as Profile does), then each
  // cell (ascending) from its composite: a UEC in closed form; an EC by a running sum from its
  // start while that is within kTailError, exactly from its end past that (no cancellation).
  TailBuffer buffer;
  double* s_at = buffer.For(list_.size());
  TailsAtComposites(ctx, s_at);
  std::size_t k = 0;
  std::size_t prefix_k = list_.size(), prefix_cells = 0;
  double prefix = 0.0;
  for (std::size_t i = 0; i < count; ++i) {
    const std::size_t x = cells[i];
    if (x >= n) {
      out[i] = w_all_free_;
      continue;
    }
    while (std::size_t{list_[k].first} + list_[k].count <= x) ++k;
    const Composite& c = list_[k];
    const std::size_t c_end = std::size_t{c.first} + c.count;
    if (c.exploded == 0) {
      out[i] = s_at[k + 1] + c.w_first * ctx.RhoPow(x - c.first) * ctx.GeomSum(c_end - x);
      continue;
    }
    const double* pool = pool_.data() + c.pool_begin;
    if (k != prefix_k) {
      prefix_k = k;
      prefix_cells = 0;
      prefix = 0.0;
    }
    prefix += PoolSum(pool + prefix_cells, x - c.first - prefix_cells);
    prefix_cells = x - c.first;
    // The difference errs by the total's bound and the sum's rounding: kept while that is
    // within kTailError of it (cells up to a trace's information end, where S has fallen to a
    // per cent of where it started, are well inside).
    const double s = s_at[k] - prefix;
    const double error =
        total_error_ + kRoundingError * static_cast<double>(prefix_cells + 2) * s_at[k];
    if (error <= kTailError * s) {
      out[i] = s;
      continue;
    }
    // This cell and the EC's later ones, from its end down.
    std::size_t last = i;
    while (last + 1 < count && cells[last + 1] < c_end) ++last;
    double part = 0.0;
    std::size_t t = c.count;
    for (std::size_t j = last + 1; j-- > i;) {
      const std::size_t to = cells[j] - c.first;
      part += PoolSum(pool + to, t - to);
      t = to;
      out[j] = s_at[k + 1] + part;
    }
    i = last;
  }
}

void UllBeam::TailSpan(const BeamContext& ctx, std::uint32_t first, std::uint32_t last,
                       std::vector<double>* out, double* total) const {
  const auto n = static_cast<std::int64_t>(ctx.cell_count());
  const auto lo = static_cast<std::int64_t>(first);
  out->resize(last - first + 1);
  double* o = out->data();   // o[c - lo] = S(c)
  double acc = w_all_free_;  // S(end of the composite being walked)
  std::int64_t c = last;     // the next cell to write, walking down
  for (; c >= lo && c >= n; --c) o[c - lo] = acc;
  for (std::size_t k = list_.size(); k-- > 0;) {
    const Composite& comp = list_[k];
    const std::int64_t begin = comp.first;
    if (c < lo || c < begin) {  // the composite lies above the span (or below: then only sums)
      acc += CompositeSum(ctx, comp);
      continue;
    }
    const std::int64_t bottom = std::max(lo, begin);
    if (comp.exploded == 0) {
      // S(x) = S(end) + w (GeomSum(count) - GeomSum(x - begin)): no dependency between cells.
      const double top = acc + comp.w_first * ctx.GeomSum(comp.count);
      const double* geom = ctx.GeomSums();
      for (std::int64_t x = bottom; x <= c; ++x) o[x - lo] = top - comp.w_first * geom[x - begin];
      acc = top;
    } else {
      // A running sum from the composite's end down through the span, then on to its start.
      const double* pool = pool_.data() + comp.pool_begin;
      double part = 0.0;
      for (std::int64_t t = comp.count; t-- > c + 1 - begin;) part += pool[t];
      for (std::int64_t x = c; x >= bottom; --x) {
        part += pool[x - begin];
        o[x - lo] = acc + part;
      }
      for (std::int64_t t = bottom - begin; t-- > 0;) part += pool[t];
      acc += part;
    }
    c = bottom - 1;
  }
  for (; c >= lo; --c) o[c - lo] = acc;
  *total = acc;
}

void UllBeam::Prefetch() const {
  // The composite list and the start of the EC pool (an ROI is typically ~1 KB of doubles).
  __builtin_prefetch(list_.data());
  const char* pool = reinterpret_cast<const char*>(pool_.data());
  const std::size_t bytes = std::min<std::size_t>(pool_.size() * sizeof(double), 1536);
  for (std::size_t at = 0; at < bytes; at += 64) __builtin_prefetch(pool + at, 1);
}

std::size_t UllBeam::MemoryBytes() const {
  return sizeof(*this) + list_.capacity() * sizeof(Composite) + pool_.capacity() * sizeof(double);
}

double UllBeam::CompositeModel(const BeamContext& ctx, std::size_t index,
                               std::size_t outcome) const {
  const Composite& c = list_.at(index);
  if (c.exploded != 0) return CompositeModelExact(ctx, index, outcome);
  const ForwardModel& model = ctx.model();
  const std::size_t first = c.first;
  const std::size_t last = first + c.count - 1;
  if (c.count == 1) return model.Probability(first, outcome);
  // Weights relative to w_first (the common factor cancels in the ratio).
  if (c.count == 2) {
    const double wa = 1.0;
    const double wb = ctx.RhoPow(1);
    return (wa * model.Probability(first, outcome) + wb * model.Probability(last, outcome)) /
           (wa + wb);
  }
  const std::size_t mid = first + (c.count - 1) / 2;
  const double wa = 1.0;
  const double wm = 4.0 * ctx.RhoPow(mid - first);
  const double wb = ctx.RhoPow(last - first);
  const double norm = wa + wm + wb;
  if (!(norm > 0.0)) return model.Probability(first, outcome);
  return (wa * model.Probability(first, outcome) + wm * model.Probability(mid, outcome) +
          wb * model.Probability(last, outcome)) /
         norm;
}

double UllBeam::CompositeModelExact(const BeamContext& ctx, std::size_t index,
                                    std::size_t outcome) const {
  const Composite& c = list_.at(index);
  const ForwardModel& model = ctx.model();
  double num = 0.0;
  double den = 0.0;
  for (std::uint32_t t = 0; t < c.count; ++t) {
    const double w = c.exploded != 0 ? pool_[c.pool_begin + t] : ctx.RhoPow(t);
    num += w * model.Probability(c.first + t, outcome);
    den += w;
  }
  return den > 0.0 ? num / den : model.Probability(c.first, outcome);
}

// Instantiated here, next to UllBeam::Update, which then inlines into UpdateMany.
std::unique_ptr<BeamStore> detail::MakeUllBeamStore(std::shared_ptr<const BeamContext> context,
                                                    std::size_t beam_count) {
  return std::make_unique<detail::BeamStoreOf<UllBeam>>(std::move(context), beam_count);
}

}  // namespace fusion
