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

// Beams are made when first updated: an untouched beam costs one slot index, and every read of
// it is answered by one shared beam at the prior (a laser's fine grid is mostly untouched: the
// laser_3d preset's 753 k beams cost ~100 MB made eagerly, ~3 MB as slots).
template <class Beam>
class BeamStoreOf final : public BeamStore {
 public:
  BeamStoreOf(std::shared_ptr<const BeamContext> ctx, std::size_t beams)
      : ctx_(std::move(ctx)), prior_(*ctx_), slot_(beams, kUnmade) {}
  std::size_t beam_count() const override { return slot_.size(); }
  double Update(std::size_t beam, std::size_t outcome) override {
    return Made(beam).Update(*ctx_, outcome);
  }
  void UpdateMany(const BeamOutcome* updates, std::size_t count, double* roi_masses) override {
    // Every beam is made first: making one may move the others.
    for (std::size_t k = 0; k < count; ++k) (void)Made(updates[k].beam);
    constexpr std::size_t kAhead = 4;
    for (std::size_t k = 0; k < count && k < kAhead; ++k) At(updates[k].beam).Prefetch();
    for (std::size_t k = 0; k < count; ++k) {
      if (k + kAhead < count) At(updates[k + kAhead].beam).Prefetch();
      const double mass = beams_[slot_[updates[k].beam]].Update(*ctx_, updates[k].outcome);
      if (roi_masses != nullptr) roi_masses[k] = mass;
    }
  }
  void Weights(std::size_t beam, std::vector<double>* weights) const override {
    At(beam).Weights(*ctx_, weights);
  }
  void TailMasses(std::size_t beam, const std::uint32_t* cells, std::size_t count,
                  double* out) const override {
    At(beam).TailMasses(*ctx_, cells, count, out);
  }
  void TailSpan(std::size_t beam, std::uint32_t first, std::uint32_t last, std::vector<double>* out,
                double* total) const override {
    At(beam).TailSpan(*ctx_, first, last, out, total);
  }
  std::uint32_t TailDropCell(std::size_t beam, std::uint32_t from, double fraction) const override {
    return At(beam).TailDropCell(*ctx_, from, fraction);
  }
  BeamProfileCells Profile(std::size_t beam, std::uint32_t from, double tail_fraction,
                           double free_ratio) const override {
    return At(beam).Profile(*ctx_, from, tail_fraction, free_ratio);
  }
  bool Touched(std::size_t beam) const override {
    return slot_[beam] != kUnmade && beams_[slot_[beam]].touched();
  }
  // Made beams stay made (their memory is reused when the grid fills up again).
  void Reset() override {
    for (Beam& b : beams_) b.Reset(*ctx_);
  }
  void ResetBeam(std::size_t beam) override {
    if (slot_[beam] != kUnmade) beams_[slot_[beam]].Reset(*ctx_);
  }
  std::size_t MemoryBytes() const override {
    std::size_t bytes = sizeof(*this) + prior_.MemoryBytes() - sizeof(Beam) +
                        slot_.capacity() * sizeof(std::uint32_t) +
                        (beams_.capacity() - beams_.size()) * sizeof(Beam);
    for (const Beam& b : beams_) bytes += b.MemoryBytes();
    return bytes;
  }

 private:
  static constexpr std::uint32_t kUnmade = 0xffffffffu;
  const Beam& At(std::size_t beam) const {
    const std::uint32_t slot = slot_[beam];
    return slot == kUnmade ? prior_ : beams_[slot];
  }
  Beam& Made(std::size_t beam) {
    std::uint32_t& slot = slot_[beam];
    if (slot == kUnmade) {
      slot = static_cast<std::uint32_t>(beams_.size());
      beams_.emplace_back(*ctx_);
    }
    return beams_[slot];
  }

  std::shared_ptr<const BeamContext> ctx_;
  Beam prior_;                       // what every unmade beam reports
  std::vector<std::uint32_t> slot_;  // per beam: its index in beams_, or kUnmade
  std::vector<Beam> beams_;          // the made beams, in the order they were first updated
};

// Each defined next to its representation (dense_beam.cc, ull_beam.cc); MakeBeamStore picks.
[[nodiscard]] std::unique_ptr<BeamStore> MakeDenseBeamStore(
    std::shared_ptr<const BeamContext> context, std::size_t beam_count);
[[nodiscard]] std::unique_ptr<BeamStore> MakeUllBeamStore(
    std::shared_ptr<const BeamContext> context, std::size_t beam_count);

}  // namespace fusion::detail
