// Internal to core: the one BeamStore implementation, a vector of beams of one representation
// over a shared BeamContext. A template in a header so that each representation's file
// instantiates it next to its beam's Update, which the compiler can then inline into UpdateMany
// (the integrator's inner loop).
#pragma once

#include <memory>
#include <utility>
#include <vector>

#include "fusion/core/beam.h"

namespace fusion::detail {

template <class Beam>
class BeamStoreOf final : public BeamStore {
 public:
  BeamStoreOf(std::shared_ptr<const BeamContext> ctx, std::size_t beams) : ctx_(std::move(ctx)) {
    beams_.reserve(beams);
    for (std::size_t b = 0; b < beams; ++b) beams_.emplace_back(*ctx_);
  }
  std::size_t beam_count() const override { return beams_.size(); }
  double Update(std::size_t beam, std::size_t outcome) override {
    return beams_[beam].Update(*ctx_, outcome);
  }
  void UpdateMany(const BeamOutcome* updates, std::size_t count, double* roi_masses) override {
    constexpr std::size_t kAhead = 4;
    for (std::size_t k = 0; k < count && k < kAhead; ++k) beams_[updates[k].beam].Prefetch();
    for (std::size_t k = 0; k < count; ++k) {
      if (k + kAhead < count) beams_[updates[k + kAhead].beam].Prefetch();
      const double mass = beams_[updates[k].beam].Update(*ctx_, updates[k].outcome);
      if (roi_masses != nullptr) roi_masses[k] = mass;
    }
  }
  void Weights(std::size_t beam, std::vector<double>* weights) const override {
    beams_[beam].Weights(*ctx_, weights);
  }
  void TailMasses(std::size_t beam, const std::vector<std::uint32_t>& cells,
                  std::vector<double>* out) const override {
    beams_[beam].TailMasses(*ctx_, cells, out);
  }
  void TailSpan(std::size_t beam, std::uint32_t first, std::uint32_t last, std::vector<double>* out,
                double* total) const override {
    beams_[beam].TailSpan(*ctx_, first, last, out, total);
  }
  std::uint32_t TailDropCell(std::size_t beam, std::uint32_t from, double fraction) const override {
    return beams_[beam].TailDropCell(*ctx_, from, fraction);
  }
  BeamProfileCells Profile(std::size_t beam, std::uint32_t from, double tail_fraction,
                           double free_ratio) const override {
    return beams_[beam].Profile(*ctx_, from, tail_fraction, free_ratio);
  }
  bool Touched(std::size_t beam) const override { return beams_[beam].touched(); }
  void Reset() override {
    for (Beam& b : beams_) b.Reset(*ctx_);
  }
  void ResetBeam(std::size_t beam) override { beams_[beam].Reset(*ctx_); }
  std::size_t MemoryBytes() const override {
    std::size_t bytes = sizeof(*this) + (beams_.capacity() - beams_.size()) * sizeof(Beam);
    for (const Beam& b : beams_) bytes += b.MemoryBytes();
    return bytes;
  }

 private:
  std::shared_ptr<const BeamContext> ctx_;
  std::vector<Beam> beams_;
};

// Each defined next to its representation (dense_beam.cc, ull_beam.cc); MakeBeamStore picks.
[[nodiscard]] std::unique_ptr<BeamStore> MakeDenseBeamStore(
    std::shared_ptr<const BeamContext> context, std::size_t beam_count);
[[nodiscard]] std::unique_ptr<BeamStore> MakeUllBeamStore(
    std::shared_ptr<const BeamContext> context, std::size_t beam_count);

}  // namespace fusion::detail
