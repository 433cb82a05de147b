// Rendering a sensor's beam grid into a local Cartesian grid (paper Sec. IV:
// "cell occupancy probabilities are computed using (8) and written to a local
// occupancy grid using ray-tracing, keeping in mind the relative offsets of the
// sensors").
//
// The local grid is keyed by OctoMap keys of the world-frame map at the same
// resolution, so a rendered grid fuses into the world octree voxel by voxel
// without resampling.
#pragma once

#include <octomap/OcTree.h>

#include <Eigen/Geometry>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "fusion/core/beam_grid.h"

namespace fusion {

// How the opinions of several beam segments that cross one voxel become one
// probability. Each segment contributes its evidence e = logit(p_segment) -
// logit(prior(segment length)), i.e. log-odds relative to what an untouched
// beam reports, weighted by its crossing length.
enum class VoxelCombine {
  // Length-weighted mean of the segments' evidence.
  kWeightedMeanLogOdds,
  // The segment with the largest evidence wins (obstacle-conservative). The default
  // (RenderOptions::kDefaultCombine): the best Brier score, recall and precision on the paper
  // scene (docs/mapping.md, "Several segments in one voxel").
  kMaxLogOdds,
  // Sum of the segments' evidence (treats overlapping beams as independent
  // observations).
  kIndependentPool,
};

// How a beam grid becomes map voxels (docs/mapping.md).
enum class RenderMethod {
  // Top-down over octree blocks against a pyramid of the beams (RenderProjective): free and
  // unknown space decided block by block, rays traced only through each beam's first-hit mass.
  kProjective,
  // Every ray traced voxel by voxel from r_min on (RenderBeamGrid): slow and obvious, the
  // oracle of the projective render.
  kRayTraced,
};

struct RenderOptions {
  static constexpr double kDefaultResolutionM = 0.02;
  // Voxel edges IsValid accepts: at 1 mm OctoMap's keys reach +-33 m from the origin; at 10 m
  // one voxel holds a building.
  static constexpr double kMinResolutionM = 0.001;
  static constexpr double kMaxResolutionM = 10.0;
  static constexpr RenderMethod kDefaultMethod = RenderMethod::kProjective;
  static constexpr VoxelCombine kDefaultCombine = VoxelCombine::kMaxLogOdds;
  static constexpr double kDefaultTailMass = 1e-2;
  static constexpr double kDefaultFreeRatio = 0.03;
  static constexpr int kDefaultMaxSubraysPerAxis = 3;
  static constexpr double kDefaultMaxRangeM = 1e9;  // no limit but the beams' own length
  static constexpr bool kDefaultFollowSurfaces = true;
  static constexpr double kDefaultMinIncidenceDeg = 3.0;
  static constexpr int kDefaultMaxSurfaceSubraysPerAxis = 8;
  static constexpr double kDefaultMaxAbsLogOdds = 12.0;
  static constexpr unsigned kDefaultThreads = 1;
  // Each thread renders into a grid of its own: more than this is a mistake, not a machine.
  static constexpr unsigned kMaxThreads = 256;

  double resolution_m = kDefaultResolutionM;
  RenderMethod method = kDefaultMethod;
  VoxelCombine combine = kDefaultCombine;
  // Projective render: a beam's free zone ends at the first cell whose occupancy p(m) exceeds
  // this fraction of the prior's (BeamGrid::Profile); a block wholly in front of the free zone's
  // end in every beam it overlaps is free as a whole, its evidence about log(free_ratio) or less.
  double free_ratio = kDefaultFreeRatio;
  // A ray stops after the voxel where the remaining first-hit mass S (relative
  // to where the rendering started) falls below this: everything behind carries
  // no information.
  double tail_mass = kDefaultTailMass;
  // A beam wider than a voxel at the range where its evidence ends is traced
  // with k x k sub-rays spread over its spherical sector, k = ceil(width *
  // range / resolution) <= this.
  int max_subrays_per_axis = kDefaultMaxSubraysPerAxis;
  // Rays are traced no further than this (metres from the sensor origin).
  double max_range_m = kDefaultMaxRangeM;
  // A beam whose surface runs on into a neighbouring beam's (their first-hit medians differ by
  // less than the incidence min_incidence_deg allows) is traced with sub-rays across its sector,
  // each carrying the beam's first-hit distribution moved to the range interpolated between the
  // two surfaces: a floor seen at a shallow angle is then continuous between the rows of beams
  // (docs/mapping.md, "Surfaces between beams"). At most max_surface_subrays_per_axis a side.
  // With the max voxel rule only.
  bool follow_surfaces = kDefaultFollowSurfaces;
  double min_incidence_deg = kDefaultMinIncidenceDeg;
  int max_surface_subrays_per_axis = kDefaultMaxSurfaceSubraysPerAxis;
  // Each segment's evidence is clamped to +-this (natural log-odds).
  double max_abs_log_odds = kDefaultMaxAbsLogOdds;
  // Threads that trace beams (each into its own grid, merged at the end; the result is the
  // same up to float rounding of the mean / pool sums). 0: one per hardware thread.
  unsigned threads = kDefaultThreads;

  // True if a render can run with these options; else false, and *why (if not null) says what
  // is wrong, starting with the field's name ("max_range_m must be finite and > 0").
  [[nodiscard]] bool IsValid(std::string* why = nullptr) const;
};

struct RenderStats {
  std::size_t beams_rendered = 0;
  std::size_t beams_untouched = 0;  // skipped: no reading, no information
  std::size_t rays_traced = 0;
  std::size_t segments = 0;  // voxel crossings with evidence
  std::size_t voxels = 0;    // distinct voxels in the local grid (projective: voxels traced)
  // Projective render: nodes of the result decided as whole blocks above voxel size, and
  // single voxels.
  std::size_t coarse_nodes = 0;
  std::size_t fine_voxels = 0;
  // Blocks left out because the map holds them free at the clamp (SaturatedFree).
  std::size_t skipped_saturated = 0;
};

// OctoMap's keys cover 32768 voxels on either side of the origin on every axis: a world point
// lies in the map iff -MapHalfExtentM(res) <= p_a < MapHalfExtentM(res) for each axis (at 2 cm,
// +-655 m). Beyond, a key would wrap around to the far side of the map.
[[nodiscard]] double MapHalfExtentM(double resolution_m);
[[nodiscard]] bool InsideMap(const Eigen::Vector3d& p_world, double resolution_m);

// World-frame voxel key of a point at the given resolution; identical to
// octomap::OcTree(resolution_m).coordToKey(p) (tree depth 16). The point must be InsideMap.
[[nodiscard]] octomap::OcTreeKey KeyOfPoint(const Eigen::Vector3d& p_world, double resolution_m);
// Centre of a voxel, world frame, metres.
[[nodiscard]] Eigen::Vector3d KeyCenter(const octomap::OcTreeKey& key, double resolution_m);

// A sparse grid of voxel evidence (open addressing hash table keyed by packed
// OcTreeKey).
class LocalGrid {
 public:
  explicit LocalGrid(double resolution_m,
                     VoxelCombine combine = RenderOptions::kDefaultCombine);

  [[nodiscard]] double resolution_m() const { return resolution_m_; }
  [[nodiscard]] VoxelCombine combine() const { return combine_; }
  [[nodiscard]] std::size_t size() const { return size_; }
  [[nodiscard]] bool empty() const { return size_ == 0; }

  // Adds one segment's evidence (log-odds relative to the prior) with a weight
  // (> 0).
  void AddEvidence(const octomap::OcTreeKey& key, double log_odds_evidence, double weight);
  // Combined occupancy probability of a voxel; std::nullopt if no segment
  // touched it.
  [[nodiscard]] std::optional<double> Probability(const octomap::OcTreeKey& key) const;
  [[nodiscard]] std::optional<double> LogOddsOf(const octomap::OcTreeKey& key) const;
  // Every voxel with its combined log-odds (unordered).
  [[nodiscard]] std::vector<std::pair<octomap::OcTreeKey, float>> LogOddsVoxels() const;
  template <typename F>
  void ForEachLogOdds(F&& f) const {
    for (const Entry& e : entries_) {
      if (e.packed != kEmpty) f(Unpack(e.packed), CombinedLogOdds(e));
    }
  }
  // Makes room for this many voxels without growing.
  void Reserve(std::size_t voxels);
  // Folds another grid of the same resolution and rule into this one, as if its segments had
  // been added here.
  void Merge(const LocalGrid& other);
  void Clear();
  [[nodiscard]] std::size_t MemoryBytes() const { return entries_.capacity() * sizeof(Entry); }

 private:
  static constexpr std::uint64_t kEmpty = ~std::uint64_t{0};
  // 16 bytes: what the combination rule needs, nothing more.
  //   mean: a = sum of w * e, b = sum of w;  max: a = max e;  pool: a = sum of
  //   e.
  struct Entry {
    std::uint64_t packed = kEmpty;
    float a = 0.0f;
    float b = 0.0f;
  };
  static std::uint64_t Pack(const octomap::OcTreeKey& key) {
    return std::uint64_t{key.k[0]} | (std::uint64_t{key.k[1]} << 16) |
           (std::uint64_t{key.k[2]} << 32);
  }
  static octomap::OcTreeKey Unpack(std::uint64_t packed) {
    return octomap::OcTreeKey(static_cast<octomap::key_type>(packed & 0xffff),
                              static_cast<octomap::key_type>((packed >> 16) & 0xffff),
                              static_cast<octomap::key_type>((packed >> 32) & 0xffff));
  }
  [[nodiscard]] float CombinedLogOdds(const Entry& e) const;
  // Slot holding `packed`, or the empty slot where it goes (grows the table first if needed).
  std::size_t SlotOf(std::uint64_t packed);
  // Folds terms (a, b) into the entry at `slot` (claiming it for `packed` if empty) by the
  // combination rule.
  void Fold(std::size_t slot, std::uint64_t packed, float a, float b);
  [[nodiscard]] const Entry* Find(std::uint64_t packed) const;
  void Grow();

  double resolution_m_;
  VoxelCombine combine_;
  std::vector<Entry> entries_;
  std::size_t size_ = 0;
  std::size_t mask_ = 0;
  std::size_t last_ = 0;  // slot of the last voxel touched: consecutive
                          // segments often repeat it
};

// Ray-traces every touched beam of the grid from the sensor pose T_world_sensor
// (sensor optical frame -> world, mount offsets included) into a local grid at
// options.resolution_m. Each voxel a ray crosses between r_min and the point
// where the beam's evidence is exhausted gets the beam's interval occupancy
// over exactly its crossing interval (BeamGrid:: IntervalOccupancy), so beam
// cells finer than a voxel are aggregated exactly. Voxels crossed by no touched
// beam, cells below r_min and voxels behind surfaces are left out (unknown).
[[nodiscard]] LocalGrid RenderBeamGrid(const BeamGrid& grid,
                                       const Eigen::Isometry3d& T_world_sensor,
                                       const RenderOptions& options, RenderStats* stats = nullptr);

}  // namespace fusion
