#include "fusion/core/local_grid.h"

#include <algorithm>
#include <cmath>
#include <exception>
#include <limits>
#include <stdexcept>
#include <thread>

namespace fusion {
namespace {

constexpr int kTreeMaxVal = 32768;  // octomap tree_max_val for depth 16
constexpr std::size_t kChunkSegments = 256;
constexpr std::size_t kRowsPerBlock = 4;
constexpr double kProbabilityFloor = 1e-9;

double Logit(double p) {
  p = std::clamp(p, kProbabilityFloor, 1.0 - kProbabilityFloor);
  return std::log(p / (1.0 - p));
}

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

// The probe sequence of a key: the key's slot in the following blocks of kBrickSlots (a
// brick's voxels keep their offsets, and neighbouring bricks do not pile up in one run as
// with linear probing), and after a whole round of blocks the next offset, so that every slot
// is reached.
class Probe {
 public:
  Probe(std::uint64_t packed, std::size_t mask)
      : slot_(HashPacked(packed) & mask), mask_(mask), round_mask_((mask + 1) / kBrickSlots - 1) {}
  [[nodiscard]] std::size_t slot() const { return slot_; }
  void Next() {
    ++step_;
    slot_ = (slot_ + kBrickSlots + ((step_ & round_mask_) == 0 ? 1 : 0)) & mask_;
  }

 private:
  std::size_t slot_;
  std::size_t mask_;
  std::size_t round_mask_;
  std::size_t step_ = 0;
};

// One voxel crossing of a ray with its evidence.
struct Segment {
  octomap::OcTreeKey key;
  float evidence;
  float weight;
  double t_out_m;  // range where the ray leaves the voxel
};

// Prior log-odds of an interval of n beam cells, cached by n.
class PriorCache {
 public:
  PriorCache(const BeamGrid& grid) : grid_(grid), cell_m_(grid.options().cell_size_m) {}
  double LogOddsOfCells(long n) {
    if (n < 0) n = 0;
    const auto index = static_cast<std::size_t>(n);
    if (index >= cache_.size()) {
      cache_.resize(index + 1, std::numeric_limits<double>::quiet_NaN());
    }
    double& v = cache_[index];
    if (std::isnan(v)) v = Logit(grid_.PriorOccupancy(static_cast<double>(n) * cell_m_));
    return v;
  }

 private:
  const BeamGrid& grid_;
  double cell_m_;
  std::vector<double> cache_;
};

// Traces one ray of one beam (Amanatides & Woo voxel traversal) and appends its
// segments. Returns the range at which the trace stopped.
class RayTracer {
 public:
  RayTracer(const BeamGrid& grid, const RenderOptions& options)
      : grid_(grid),
        options_(options),
        prior_(grid),
        cell_m_(grid.options().cell_size_m),
        inv_res_(1.0 / options.resolution_m) {
    boundaries_.reserve(kChunkSegments + 1);
    keys_.reserve(kChunkSegments);
  }

  double Trace(std::size_t beam, const Eigen::Vector3d& origin, const Eigen::Vector3d& dir,
               double t_start, double t_end, float weight_scale, std::vector<Segment>* out) {
    if (!(t_end > t_start)) return t_start;
    // Voxels beyond the cell where the remaining first-hit mass falls below tail_mass are
    // never reached: the loop below stops there. Entering no voxel past that cell saves the
    // traversal and the interval lookups of a whole chunk behind every surface; the voxel
    // holding the cell is still crossed whole.
    const double t_last_entry =
        std::min(t_end, grid_.InformationEndM(beam, t_start, options_.tail_mass) + cell_m_);
    const double res = options_.resolution_m;
    const Eigen::Vector3d p0 = origin + dir * t_start;
    long index[3];
    int step[3];
    double t_max[3];
    double t_delta[3];
    for (int a = 0; a < 3; ++a) {
      index[a] = static_cast<long>(std::floor(p0[a] * inv_res_));
      if (dir[a] > 0.0) {
        step[a] = 1;
        t_max[a] = t_start + ((index[a] + 1) * res - p0[a]) / dir[a];
        t_delta[a] = res / dir[a];
      } else if (dir[a] < 0.0) {
        step[a] = -1;
        t_max[a] = t_start + (index[a] * res - p0[a]) / dir[a];
        t_delta[a] = -res / dir[a];
      } else {
        step[a] = 0;
        t_max[a] = std::numeric_limits<double>::infinity();
        t_delta[a] = std::numeric_limits<double>::infinity();
      }
    }
    double remaining_mass = 1.0;
    double t_in = t_start;
    bool done = false;
    while (!done) {
      boundaries_.clear();
      keys_.clear();
      boundaries_.push_back(t_in);
      while (keys_.size() < kChunkSegments && t_in < t_last_entry) {
        const int axis =
            (t_max[0] < t_max[1]) ? (t_max[0] < t_max[2] ? 0 : 2) : (t_max[1] < t_max[2] ? 1 : 2);
        const double t_out = std::min(t_max[axis], t_end);
        keys_.emplace_back(static_cast<octomap::key_type>(index[0] + kTreeMaxVal),
                           static_cast<octomap::key_type>(index[1] + kTreeMaxVal),
                           static_cast<octomap::key_type>(index[2] + kTreeMaxVal));
        boundaries_.push_back(t_out);
        t_in = t_out;
        index[axis] += step[axis];
        t_max[axis] += t_delta[axis];
      }
      if (keys_.empty()) break;
      grid_.IntervalOccupancy(beam, boundaries_, &occupancy_);
      long c1 = std::lround(boundaries_[0] / cell_m_);
      for (std::size_t j = 0; j < keys_.size(); ++j) {
        const long c0 = c1;
        c1 = std::lround(boundaries_[j + 1] / cell_m_);
        if (c1 <= c0) continue;  // shorter than a beam cell: no evidence of its own
        const double p = j < occupancy_.size() ? occupancy_[j] : 0.5;
        double evidence = Logit(p) - prior_.LogOddsOfCells(c1 - c0);
        evidence = std::clamp(evidence, -options_.max_abs_log_odds, options_.max_abs_log_odds);
        const double length_m = boundaries_[j + 1] - boundaries_[j];
        out->push_back({keys_[j], static_cast<float>(evidence),
                        static_cast<float>(length_m) * weight_scale, boundaries_[j + 1]});
        remaining_mass *= (1.0 - p);
        if (remaining_mass < options_.tail_mass) {
          done = true;
          t_in = boundaries_[j + 1];
          break;
        }
      }
      if (t_in >= t_last_entry) done = true;
    }
    return t_in;
  }

 private:
  const BeamGrid& grid_;
  const RenderOptions& options_;
  PriorCache prior_;
  double cell_m_;
  double inv_res_;
  std::vector<double> boundaries_;
  std::vector<octomap::OcTreeKey> keys_;
  std::vector<double> occupancy_;
};

}  // namespace

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

namespace {

// Renders the beams of `rows` (row-major beam order) into `local`.
void RenderRows(const BeamGrid& grid, const Eigen::Isometry3d& T_world_sensor,
                const RenderOptions& options, const std::vector<std::size_t>& rows,
                LocalGrid& local, RenderStats& s) {
  const SensorSpec& spec = grid.spec();
  const BeamTessellation& tess = grid.tessellation();
  const double beam_length_m =
      static_cast<double>(grid.cells_per_beam()) * grid.options().cell_size_m;
  const double t_start = std::max(0.0, spec.r_min_m);
  const double t_end = std::min(beam_length_m, options.max_range_m);
  const double width_rad = std::max(tess.beam_width_h_rad(), tess.beam_width_v_rad());
  const Eigen::Matrix3d R = T_world_sensor.linear();
  const Eigen::Vector3d origin = T_world_sensor.translation();

  RayTracer tracer(grid, options);
  std::vector<Segment> segments;
  segments.reserve(512);
  const auto cols = static_cast<std::size_t>(tess.cols());
  for (const std::size_t row : rows) {
    for (std::size_t b = row * cols; b < (row + 1) * cols; ++b) {
      if (!grid.Touched(b)) {
        ++s.beams_untouched;
        continue;
      }
      ++s.beams_rendered;
      segments.clear();
      const Eigen::Vector3d dir_sensor = tess.Direction(b);
      const double t_stop =
          tracer.Trace(b, origin, R * dir_sensor, t_start, t_end, 1.0f, &segments);
      ++s.rays_traced;
      const int k =
          std::clamp(static_cast<int>(std::ceil(width_rad * t_stop / options.resolution_m)), 1,
                     std::max(1, options.max_subrays_per_axis));
      if (k > 1) {
        // The beam's footprint outgrows a voxel at r_split = resolution / width:
        // keep the centre ray up to there and spread k x k sub-rays uniformly
        // over its azimuth x elevation sector beyond, each with weight 1 / k^2.
        const double r_split = options.resolution_m / width_rad;
        double t_sub = t_start;
        std::size_t keep = 0;
        while (keep < segments.size() && segments[keep].t_out_m <= r_split) {
          t_sub = segments[keep].t_out_m;
          ++keep;
        }
        segments.resize(keep);
        const double az = std::atan2(dir_sensor.x(), dir_sensor.z());
        const double el = std::atan2(-dir_sensor.y(), std::hypot(dir_sensor.x(), dir_sensor.z()));
        const float weight = 1.0f / static_cast<float>(k * k);
        for (int i = 0; i < k; ++i) {
          const double sub_az = az + ((i + 0.5) / k - 0.5) * tess.beam_width_h_rad();
          for (int j = 0; j < k; ++j) {
            const double sub_el = el + ((j + 0.5) / k - 0.5) * tess.beam_width_v_rad();
            const Eigen::Vector3d d(std::cos(sub_el) * std::sin(sub_az), -std::sin(sub_el),
                                    std::cos(sub_el) * std::cos(sub_az));
            tracer.Trace(b, origin, R * d, t_sub, t_end, weight, &segments);
            ++s.rays_traced;
          }
        }
      }
      s.segments += segments.size();
      for (const Segment& seg : segments) local.AddEvidence(seg.key, seg.evidence, seg.weight);
    }
  }
}

}  // namespace

LocalGrid RenderBeamGrid(const BeamGrid& grid, const Eigen::Isometry3d& T_world_sensor,
                         const RenderOptions& options, RenderStats* stats) {
  const auto rows = static_cast<std::size_t>(grid.tessellation().rows());
  std::size_t threads =
      options.threads != 0 ? options.threads : std::max(1u, std::thread::hardware_concurrency());
  threads = std::clamp<std::size_t>(threads, 1, std::max<std::size_t>(1, rows / kRowsPerBlock));
  // Blocks of rows dealt out in turn, so that every thread gets its share of the beams that
  // see far (long rays) and of those that hit something near.
  std::vector<std::vector<std::size_t>> rows_of(threads);
  for (std::size_t r = 0; r < rows; ++r) rows_of[(r / kRowsPerBlock) % threads].push_back(r);
  std::vector<LocalGrid> parts(threads, LocalGrid(options.resolution_m, options.combine));
  std::vector<RenderStats> part_stats(threads);
  std::vector<std::exception_ptr> errors(threads);
  const auto work = [&](std::size_t t) {
    try {
      RenderRows(grid, T_world_sensor, options, rows_of[t], parts[t], part_stats[t]);
    } catch (...) {
      errors[t] = std::current_exception();
    }
  };
  std::vector<std::thread> helpers;
  for (std::size_t t = 1; t < threads; ++t) helpers.emplace_back(work, t);
  work(0);
  for (std::thread& h : helpers) h.join();
  for (const auto& e : errors) {
    if (e) std::rethrow_exception(e);
  }
  LocalGrid local = std::move(parts[0]);
  RenderStats s = part_stats[0];
  for (std::size_t t = 1; t < threads; ++t) {
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
