#include "fusion/core/local_grid.h"

#include <algorithm>
#include <cmath>
#include <exception>
#include <limits>
#include <stdexcept>
#include <string>
#include <thread>

#include "beam_trace.h"

namespace fusion {
namespace {

constexpr int kTreeMaxVal = 32768;  // octomap tree_max_val for depth 16

// Slot of a key: the 4 x 4 x 4 brick around the voxel is hashed (murmur3
// finaliser) and the voxel's position inside the brick is added, so
// neighbouring voxels share cache lines while a ray is traced and the table
// iterates in brick order (cache-friendly fusion into the octree).
std::uint64_t HashPacked(std::uint64_t packed) {
  const std::uint64_t local = (packed & 0x3) | ((packed >> 14) & 0xc) | ((packed >> 28) & 0x30);
  std::uint64_t x =
      packed & ~((std::uint64_t{3}) | (std::uint64_t{3} << 16) | (std::uint64_t{3} << 32));
  x ^= x >> 33;
  x *= 0xff51afd7ed558ccdull;
  x ^= x >> 33;
  return (x << 6) + local;
}

// Slots of a 4 x 4 x 4 brick (HashPacked).
constexpr std::size_t kBrickSlots = 64;

// The probe sequence of a key: the key's slot, then one block of kBrickSlots on and one offset
// further each step (65 is odd, so a power-of-two table is visited whole). The offset must move:
// a surface fills a few offsets of every brick it crosses (a floor: the 16 of one z layer), and
// probing only at the key's own offset would run through the whole table's worth of them.
class Probe {
 public:
  Probe(std::uint64_t packed, std::size_t mask) : slot_(HashPacked(packed) & mask), mask_(mask) {}
  [[nodiscard]] std::size_t slot() const { return slot_; }
  void Next() { slot_ = (slot_ + kBrickSlots + 1) & mask_; }

 private:
  std::size_t slot_;
  std::size_t mask_;
};

}  // namespace

bool RenderOptions::IsValid(std::string* why) const {
  const auto fail = [why](const char* message) {
    if (why != nullptr) *why = message;
    return false;
  };
  if (!(resolution_m >= kMinResolutionM && resolution_m <= kMaxResolutionM)) {
    return fail("resolution_m must lie in [0.001, 10] m");
  }
  if (!(free_ratio > 0.0 && std::isfinite(free_ratio))) {
    return fail("free_ratio must be finite and > 0");
  }
  if (!(tail_mass > 0.0 && tail_mass < 1.0)) return fail("tail_mass must lie in (0, 1)");
  if (max_subrays_per_axis < 1) return fail("max_subrays_per_axis must be >= 1");
  if (!(max_range_m > 0.0 && std::isfinite(max_range_m))) {
    return fail("max_range_m must be finite and > 0");
  }
  if (!(min_incidence_deg > 0.0 && min_incidence_deg < 90.0)) {
    return fail("min_incidence_deg must lie in (0, 90)");
  }
  if (max_surface_subrays_per_axis < 1) return fail("max_surface_subrays_per_axis must be >= 1");
  if (!(max_abs_log_odds > 0.0 && std::isfinite(max_abs_log_odds))) {
    return fail("max_abs_log_odds must be finite and > 0");
  }
  if (threads > kMaxThreads) return fail("threads must lie in 0..256");
  return true;
}

double MapHalfExtentM(double resolution_m) { return kTreeMaxVal * resolution_m; }

bool InsideMap(const Eigen::Vector3d& p_world, double resolution_m) {
  // The voxel index, as KeyOfPoint computes it, within [-32768, 32767].
  const double inv = 1.0 / resolution_m;
  for (int a = 0; a < 3; ++a) {
    const double index = std::floor(inv * p_world[a]);
    if (!(index >= -kTreeMaxVal && index < kTreeMaxVal)) return false;  // NaN too
  }
  return true;
}

octomap::OcTreeKey KeyOfPoint(const Eigen::Vector3d& p_world, double resolution_m) {
  const double inv = 1.0 / resolution_m;
  return octomap::OcTreeKey(
      static_cast<octomap::key_type>(static_cast<int>(std::floor(inv * p_world.x())) + kTreeMaxVal),
      static_cast<octomap::key_type>(static_cast<int>(std::floor(inv * p_world.y())) + kTreeMaxVal),
      static_cast<octomap::key_type>(static_cast<int>(std::floor(inv * p_world.z())) +
                                     kTreeMaxVal));
}

Eigen::Vector3d KeyCenter(const octomap::OcTreeKey& key, double resolution_m) {
  return Eigen::Vector3d((static_cast<int>(key.k[0]) - kTreeMaxVal + 0.5) * resolution_m,
                         (static_cast<int>(key.k[1]) - kTreeMaxVal + 0.5) * resolution_m,
                         (static_cast<int>(key.k[2]) - kTreeMaxVal + 0.5) * resolution_m);
}

LocalGrid::LocalGrid(double resolution_m, VoxelCombine combine)
    : resolution_m_(resolution_m), combine_(combine) {
  entries_.resize(1024);
  mask_ = entries_.size() - 1;
}

void LocalGrid::Clear() {
  std::fill(entries_.begin(), entries_.end(), Entry{});
  size_ = 0;
  last_ = 0;
}

void LocalGrid::Reserve(std::size_t voxels) {
  while (2 * voxels > entries_.size()) Grow();
}

void LocalGrid::Grow() {
  std::vector<Entry> old;
  old.swap(entries_);
  entries_.assign(old.size() * 2, Entry{});
  mask_ = entries_.size() - 1;
  for (const Entry& e : old) {
    if (e.packed == kEmpty) continue;
    Probe probe(e.packed, mask_);
    while (entries_[probe.slot()].packed != kEmpty) probe.Next();
    entries_[probe.slot()] = e;
  }
  last_ = 0;
}

std::size_t LocalGrid::SlotOf(std::uint64_t packed) {
  if (2 * (size_ + 1) > entries_.size()) Grow();
  Probe probe(packed, mask_);
  while (entries_[probe.slot()].packed != packed && entries_[probe.slot()].packed != kEmpty) {
    probe.Next();
  }
  return probe.slot();
}

void LocalGrid::Fold(std::size_t slot, std::uint64_t packed, float a, float b) {
  Entry& e = entries_[slot];
  const bool fresh = e.packed == kEmpty;
  if (fresh) {
    e.packed = packed;
    ++size_;
  }
  switch (combine_) {
    case VoxelCombine::kWeightedMeanLogOdds:
      e.a += a;
      e.b += b;
      break;
    case VoxelCombine::kMaxLogOdds:
      e.a = fresh ? a : std::max(e.a, a);
      break;
    case VoxelCombine::kIndependentPool:
      e.a += a;
      break;
  }
}

void LocalGrid::AddEvidence(const octomap::OcTreeKey& key, double log_odds_evidence,
                            double weight) {
  const std::uint64_t packed = Pack(key);
  if (entries_[last_].packed != packed) last_ = SlotOf(packed);
  const auto evidence = static_cast<float>(log_odds_evidence);
  const auto w = static_cast<float>(weight);
  // The entry's terms (see Entry): mean sums w * e and w; max and pool take e.
  const bool mean = combine_ == VoxelCombine::kWeightedMeanLogOdds;
  Fold(last_, packed, mean ? w * evidence : evidence, w);
}

void LocalGrid::Merge(const LocalGrid& other) {
  if (other.combine_ != combine_ || other.resolution_m_ != resolution_m_) {
    throw std::invalid_argument("LocalGrid::Merge: grids differ in resolution or rule");
  }
  // Both tables hash alike: walking the other's slots in order into a smaller table piles its
  // entries into long runs (every later lookup pays for them), into one at least as large not.
  while (entries_.size() < other.entries_.size()) Grow();
  Reserve(size_ + other.size_);
  for (const Entry& o : other.entries_) {
    if (o.packed != kEmpty) Fold(SlotOf(o.packed), o.packed, o.a, o.b);
  }
  last_ = 0;
}

const LocalGrid::Entry* LocalGrid::Find(std::uint64_t packed) const {
  for (Probe probe(packed, mask_); entries_[probe.slot()].packed != kEmpty; probe.Next()) {
    if (entries_[probe.slot()].packed == packed) return &entries_[probe.slot()];
  }
  return nullptr;
}

float LocalGrid::CombinedLogOdds(const Entry& e) const {
  switch (combine_) {
    case VoxelCombine::kWeightedMeanLogOdds:
      return e.b > 0.0f ? e.a / e.b : 0.0f;
    case VoxelCombine::kMaxLogOdds:
    case VoxelCombine::kIndependentPool:
      return e.a;
  }
  return 0.0f;
}

std::optional<double> LocalGrid::LogOddsOf(const octomap::OcTreeKey& key) const {
  const Entry* e = Find(Pack(key));
  if (e == nullptr) return std::nullopt;
  return CombinedLogOdds(*e);
}

std::optional<double> LocalGrid::Probability(const octomap::OcTreeKey& key) const {
  const auto l = LogOddsOf(key);
  if (!l) return std::nullopt;
  return 1.0 / (1.0 + std::exp(-*l));
}

std::vector<std::pair<octomap::OcTreeKey, float>> LocalGrid::LogOddsVoxels() const {
  std::vector<std::pair<octomap::OcTreeKey, float>> out;
  out.reserve(size_);
  ForEachLogOdds([&out](const octomap::OcTreeKey& k, float l) { out.emplace_back(k, l); });
  return out;
}

LocalGrid RenderBeamGrid(const BeamGrid& grid, const Eigen::Isometry3d& T_world_sensor,
                         const RenderOptions& options, RenderStats* stats) {
  const auto rows = static_cast<std::size_t>(grid.tessellation().rows());
  const auto cols = static_cast<std::size_t>(grid.tessellation().cols());
  const std::size_t workers = detail::RowWorkers(rows, options.threads);
  std::vector<LocalGrid> parts(workers, LocalGrid(options.resolution_m, options.combine));
  std::vector<RenderStats> part_stats(workers);
  const std::vector<BeamProfile> profiles =
      detail::ProfileBeams(grid, options, detail::BeamTracer::StartOf(grid), workers);
  detail::ForEachRowBlock(
      rows, workers, [&](std::size_t t, const std::vector<std::size_t>& my_rows) {
        detail::BeamTracer tracer(grid, T_world_sensor, options, profiles);
        std::vector<detail::Segment> segments;
        segments.reserve(512);
        RenderStats& s = part_stats[t];
        for (const std::size_t row : my_rows) {
          for (std::size_t b = row * cols; b < (row + 1) * cols; ++b) {
            if (!grid.Touched(b)) {
              ++s.beams_untouched;
              continue;
            }
            ++s.beams_rendered;
            segments.clear();
            s.rays_traced += tracer.TraceBeam(b, /*first_mass_only=*/false, &segments).rays;
            s.segments += segments.size();
            for (const auto& seg : segments)
              parts[t].AddEvidence(seg.key, seg.evidence, seg.weight);
          }
        }
      });
  LocalGrid local = std::move(parts[0]);
  RenderStats s = part_stats[0];
  for (std::size_t t = 1; t < workers; ++t) {
    local.Merge(parts[t]);
    s.beams_rendered += part_stats[t].beams_rendered;
    s.beams_untouched += part_stats[t].beams_untouched;
    s.rays_traced += part_stats[t].rays_traced;
    s.segments += part_stats[t].segments;
  }
  s.voxels = local.size();
  if (stats != nullptr) *stats = s;
  return local;
}

}  // namespace fusion
