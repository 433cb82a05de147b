// The fused world map and its life cycle (DESIGN.md, "Map life cycle"), and the one fusion
// path of the system.
//
// The map queries see is, region by region, FusionPolicy::Fuse over the committed history
// (an octree, coarse nodes included, which a snapshot loaded at start becomes) and every
// sensor's live contribution (the render of its open period). Replacing a sensor's live
// contribution re-fuses only the regions the old or the new one covers; committing folds it
// into the history. Every change goes through FuseRegions (octree_merge.h), and each published
// version says which regions it changed (MapChanges), for the change log.
//
// Publication: Publish() hands out the map as an immutable octree. Two trees take turns: the
// one published last is read by queries while the other is written; the other is brought up
// to date with the regions of the version it missed in the same walk as the next write
// (octree_merge.h, CatchUp), so no version is a deep copy of the map (unless a reader still
// holds the tree that is due to be written: then it is copied once).
//
// Two ways to drive it:
//  - The pieces, for a pipelined caller (fusiond): integrate with its own SensorPeriods, render
//    with Render() (projective_render.h), then ReplaceLive / CommitLive / Publish here.
//  - Integrate / Render / Commit below, which do all of that in turn on the caller's thread
//    (tests, benchmarks, the accuracy harness) and publish after each change.
//
// Frames: poses are T_world_sensor (sensor optical frame -> world); clouds are in the sensor
// frame; the octree is in the world frame. Not thread-safe: one writer; published trees may be
// read from any thread.
#pragma once

#include <octomap/OcTree.h>

#include <Eigen/Geometry>
#include <cstddef>
#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "fusion/core/beam_grid.h"
#include "fusion/core/change_log.h"
#include "fusion/core/fusion_rules.h"
#include "fusion/core/local_grid.h"
#include "fusion/core/projective_render.h"
#include "fusion/core/rendered_grid.h"
#include "fusion/core/sensor.h"
#include "fusion/core/sensor_periods.h"

namespace fusion {

struct WorldMapOptions {
  static constexpr double kDefaultResolutionM = RenderOptions::kDefaultResolutionM;
  static constexpr FusionRule kDefaultRule = FusionRule::kIndependentOpinionPool;
  static constexpr double kDefaultPoseToleranceM = 0.02;
  static constexpr double kDefaultPoseToleranceDeg = 1.0;
  static constexpr double kDefaultPoseToleranceRad =
      kDefaultPoseToleranceDeg * 3.14159265358979323846 / 180.0;
  static constexpr double kDefaultClampingMin = FusionPolicy::kDefaultClampingMin;
  static constexpr double kDefaultClampingMax = FusionPolicy::kDefaultClampingMax;
  static constexpr double kDefaultHistoryClampingMax = 0.999;
  static constexpr double kDefaultBeamPriorLengthM = 1.0;
  static constexpr double kDefaultOccupancyThreshold = 0.5;
  static constexpr double kDefaultForgetHalfLifeS = 0.0;  // never
  static constexpr float kForgottenLogOdds = 0.05f;       // |log-odds| below: unknown again

  double resolution_m = kDefaultResolutionM;
  FusionRule rule = kDefaultRule;
  // render.resolution_m is overridden by resolution_m.
  RenderOptions render;
  // beam_grid.prior_reference_length_m is overridden by beam_prior_length_m.
  BeamGridOptions beam_grid;
  // Beam prior: a run of this length starts with occupancy 0.5 (p0 per cell follows).
  // Rendering measures evidence relative to this prior, so an untouched voxel is 0.5
  // whatever it is. A short length (one voxel) makes an untouched 7.5 m beam almost certain
  // to hold something (1 - 0.5^375 at 2 cm), and then a beam needs ~20 readings before any
  // free space shows; at 1 m one frame suffices, and the accuracy table improves (Brier
  // 0.0031 -> 0.0028 for the SR-3000, see docs/mapping.md). Far-seeing lasers want 5 m (a
  // single return at 20 m then marks its surface and clears its beam); it is not the default
  // because a stereo camera's unbounded beams then carry first-hit mass much further and its
  // render traces 34 times the crossings (BENCHMARKS.md, "Occupancy that says what the
  // evidence says").
  double beam_prior_length_m = kDefaultBeamPriorLengthM;
  double pose_tolerance_m = kDefaultPoseToleranceM;
  double pose_tolerance_rad = kDefaultPoseToleranceRad;
  // Fused probabilities are clamped to [min, max] (as OctoMap does) so the map
  // stays updatable.
  double clamping_min_probability = kDefaultClampingMin;
  double clamping_max_probability = kDefaultClampingMax;
  // The committed history is clamped tighter on the occupied side (min is shared: the render
  // leaves out the history's saturated free space, which needs one free clamp): what a period
  // saw occupied is overturned by the free evidence of a few later ones, wherever a moving
  // sensor's frames or a stationary sensor's new period find it gone (docs/mapping.md, "A
  // world that changes"). A period's own evidence is not clamped by it: a sensor standing
  // still keeps its certainty until it commits. In (clamping_min, clamping_max].
  double history_clamping_max_probability = kDefaultHistoryClampingMax;
  // Evidence nobody observes again decays toward unknown with this half-life (seconds): Forget
  // scales the committed history's log-odds by 0.5^(elapsed / half-life) and drops what comes
  // within kForgottenLogOdds of 0. 0: never (the default).
  double forget_half_life_s = kDefaultForgetHalfLifeS;
  // The trees' OcTree::setOccupancyThres (what OctoMap's own readers, castRay and the .bt
  // writer, call occupied).
  double occupancy_threshold = kDefaultOccupancyThreshold;

  // True if a WorldMap can run with these options (its sensors' beam grid and render options,
  // SensorGridOptions and MapRenderOptions, included); else false, and *why (if not null) says
  // what is wrong, starting with the field's path from this struct ("resolution_m must ...",
  // "beam_grid.cell_size_m must ...", "render.max_range_m must ...").
  [[nodiscard]] bool IsValid(std::string* why = nullptr) const;
};

// The beam grid options a sensor of this map gets (the map's beam prior applied).
[[nodiscard]] BeamGridOptions SensorGridOptions(const WorldMapOptions& options);
// The same for `spec`: its own beam prior when it names one (SensorSpec::beam_prior_length_m).
[[nodiscard]] BeamGridOptions SensorGridOptions(const WorldMapOptions& options,
                                                const SensorSpec& spec);
// The render options of this map (its resolution applied).
[[nodiscard]] RenderOptions MapRenderOptions(const WorldMapOptions& options);

struct SensorCounters {
  std::uint64_t frames_integrated = 0;
  std::uint64_t frames_in_period = 0;  // since the last commit / beam grid restart
  std::uint64_t renders = 0;
  std::uint64_t commits = 0;
  std::uint64_t pose_moves = 0;  // commits caused by the pose leaving the tolerance
  std::uint64_t points_updated = 0;
  std::uint64_t points_beyond_range = 0;
  std::uint64_t points_missing = 0;
  std::uint64_t points_rejected = 0;
  std::size_t live_nodes = 0;  // nodes of the live contribution
};

struct FuseStats {
  RenderStats render;
  std::size_t regions_changed = 0;
};

// One published version of the map.
struct Publication {
  std::shared_ptr<const octomap::OcTree> tree;  // never null
  MapChanges changes;                           // changes.version is the map's version
  // tree->getNumLeafNodes(), kept by the merges that made the tree (no walk).
  std::size_t leaves = 0;
};

class WorldMap {
 public:
  explicit WorldMap(const WorldMapOptions& options = {});
  ~WorldMap();
  WorldMap(const WorldMap&) = delete;
  WorldMap& operator=(const WorldMap&) = delete;

  [[nodiscard]] const WorldMapOptions& options() const { return options_; }
  [[nodiscard]] double resolution_m() const { return options_.resolution_m; }
  [[nodiscard]] const FusionPolicy& policy() const { return policy_; }

  MapStatus AddSensor(const std::string& sensor_id, const SensorSpec& spec);
  [[nodiscard]] bool HasSensor(const std::string& sensor_id) const;
  [[nodiscard]] std::vector<std::string> SensorIds() const;

  // ---- The pieces -------------------------------------------------------------------------
  // Replaces the sensor's live contribution by `rendered` (a render of its open period) and
  // re-fuses the regions the old or the new one covers.
  MapStatus ReplaceLive(const std::string& sensor_id, RenderedGrid rendered,
                        FuseStats* stats = nullptr);
  // What a render of the sensor's open period may leave out (projective_render.h): the
  // history's saturated free space outside the other sensors' live contributions. Valid until
  // the next change of the map; empty (no history) under the max and De Morgan rules, where
  // free evidence above the clamp still moves a value held at it.
  [[nodiscard]] SaturatedFree Saturation(const std::string& sensor_id) const;
  // Folds the sensor's live contribution into the committed history; the map does not change
  // (it already holds it) unless other sensors' live contributions overlap it.
  MapStatus CommitLive(const std::string& sensor_id);
  // Buffers for renders made for this map (fusion::Render's scratch): the live contributions
  // ReplaceLive and CommitLive let go of give their memory back here. Use it from the thread
  // that calls the map's other non-const members, under the same lock.
  [[nodiscard]] RenderScratch& render_scratch() { return render_scratch_; }
  // The map so far becomes the committed history of a map that starts from it (a snapshot
  // loaded at start); every live contribution is dropped. Voxels are fused (clamped) as they
  // come in. Versions go on; the next publication is a reset.
  void LoadHistory(const octomap::OcTree& history);
  // Clears the history, every live contribution and every period; the next publication is a
  // reset.
  void Reset();
  // Forgets what the map knows in a box (world frame, closed; voxels whose centres lie in it
  // become unknown), as octomap_server's clear_bbox: every live contribution is folded into the
  // history first (CommitLive) and every sensor's period restarts (its beam grid would bring the
  // box back), then the box is removed from the history and the map, and the next publication
  // names the regions. A caller that keeps periods of its own (the service's worker, with the
  // pieces above) folds and restarts those first. Returns the voxels forgotten.
  std::uint64_t ClearBox(const Eigen::AlignedBox3d& box_world);
  // Lets elapsed_s of time pass over the committed history (options().forget_half_life_s):
  // every value's log-odds is scaled by 0.5^(elapsed_s / half-life), values that come within
  // kForgottenLogOdds of 0 are removed (unknown), and the map is re-fused. What sensors observe
  // now (their live contributions) is not decayed, and what they observe again is refreshed
  // when it is committed. Does nothing when forgetting is off or elapsed_s <= 0. Returns the
  // history leaves removed. The caller keeps the clock (the service's worker, on its renderer
  // thread). The next publication names every region of the history.
  std::uint64_t Forget(double elapsed_s);
  // Publishes the map if it changed since the last publication (a new version), else returns
  // the last one again.
  Publication Publish();

  // ---- All in turn, on the caller's thread ------------------------------------------------
  // Applies one cloud (sensor frame, 3 floats per point; beyond_range as in
  // BeamGrid::Integrate) taken at T_world_sensor. If the pose left the tolerance around the
  // current period's pose, the period is committed first (rendered if it has unrendered
  // frames) and a new period starts at the new pose. Does not render: call Render.
  MapStatus Integrate(const std::string& sensor_id, const Eigen::Isometry3d& T_world_sensor,
                      const float* points_xyz, std::size_t point_count,
                      const std::vector<std::uint8_t>& beyond_range = {},
                      IntegrationStats* stats = nullptr, bool* committed = nullptr);
  // Renders the sensor's open period and replaces its live contribution; publishes.
  MapStatus Render(const std::string& sensor_id, FuseStats* stats = nullptr);
  // Renders every sensor with unrendered frames.
  void RenderAll();
  // Folds the sensor's live contribution into the committed history and restarts its period
  // (rendered first if it has unrendered frames); publishes.
  MapStatus Commit(const std::string& sensor_id);

  // ---- The map ----------------------------------------------------------------------------
  // The fused map as it is now (world frame, log-odds per leaf, coarse leaves where a block is
  // uniform). Valid until the next change; Publish() for a tree that stays.
  [[nodiscard]] const octomap::OcTree& tree() const;
  // The version of the last publication (0: none yet).
  [[nodiscard]] std::uint64_t version() const { return version_; }
  [[nodiscard]] std::optional<SensorCounters> Counters(const std::string& sensor_id) const;
  // The beam grid of the sensor's open period (Integrate / Render above); nullptr for an
  // unknown sensor.
  [[nodiscard]] const BeamGrid* beam_grid(const std::string& sensor_id) const;
  // Fused occupancy of a world point; std::nullopt where the map has no information.
  [[nodiscard]] std::optional<double> Occupancy(const Eigen::Vector3d& p_world) const;
  // Nodes of the committed history, the working and the published trees, and of the live
  // contributions, the render buffers kept (render_scratch) and the change lists' buffers, in
  // bytes.
  [[nodiscard]] std::size_t MemoryBytes() const;
  // Publications that had to copy a tree a reader still held (see the top of this file).
  [[nodiscard]] std::uint64_t tree_copies() const { return tree_copies_; }

 private:
  struct SensorState;
  SensorState* Find(const std::string& sensor_id);
  [[nodiscard]] const SensorState* Find(const std::string& sensor_id) const;
  // The tree to write, brought up to date (see Publication above); with catch_up, the spare's
  // catching up is left to the caller's merge (*catch_up says with what, else it is empty).
  octomap::OcTree& Working(CatchUp* catch_up = nullptr);
  // FuseRegions(Working(), the map's policy, every source, drivers) catching up in the same
  // walk; the changed regions go to pending_. Returns how many.
  std::size_t FuseIntoWorking(const std::vector<const RenderedGrid*>& drivers);
  std::vector<MergeSource> Sources(const SensorState* except) const;
  // Merges the regions pending_ got from one merge (from run_begin on) into the ordered rest.
  void MergeRun(std::size_t run_begin);

  WorldMapOptions options_;
  FusionPolicy policy_;
  FusionPolicy history_policy_;  // policy_ with the history's occupied clamp
  RenderOptions render_;
  std::map<std::string, std::unique_ptr<SensorState>> sensors_;
  std::unique_ptr<octomap::OcTree> committed_;
  std::shared_ptr<octomap::OcTree> working_;    // null between Publish and the next write
  std::shared_ptr<octomap::OcTree> published_;  // never null
  std::shared_ptr<octomap::OcTree> spare_;      // the publication before, reused when free
  // Each tree's leaf count (OcTree::getNumLeafNodes), kept from the merges' reports.
  std::size_t committed_leaves_ = 0, working_leaves_ = 0, published_leaves_ = 0,
              spare_leaves_ = 0;
  std::vector<MapRegion> spare_lag_;            // regions the spare lacks
  RenderedGrid copy_driver_{1.0};               // CopyRegions' buffer, kept between calls
  std::vector<MapRegion> pending_;              // changed since the last publication
  bool pending_reset_ = false;
  std::uint64_t version_ = 0;
  Publication last_;
  std::uint64_t tree_copies_ = 0;
  RenderScratch render_scratch_;
};

}  // namespace fusion
