// The fused world map and its life cycle (DESIGN.md, "Map life cycle").
//
// Each sensor owns a beam grid that accumulates clouds while the sensor's pose
// stays within a tolerance (a "stationary period"). Rendering the period gives
// the sensor's live local grid; the map that queries see is, per voxel, the
// fusion rule applied to the committed history and every sensor's live grid.
// Re-rendering a period therefore replaces its contribution instead of adding
// it again. When the pose moves past the tolerance (or on Commit) the live grid
// is folded into the committed history and the beam grid restarts at the new
// pose.
//
// Frames: poses are T_world_sensor (sensor optical frame -> world); clouds are
// in the sensor frame; the octree is in the world frame. Not thread-safe: one
// writer, callers serialise.
#pragma once

#include <octomap/OcTree.h>

#include <Eigen/Geometry>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <unordered_map>
#include <vector>

#include "fusion/core/beam_grid.h"
#include "fusion/core/fusion_rules.h"
#include "fusion/core/local_grid.h"
#include "fusion/core/sensor.h"

namespace fusion {

struct WorldMapOptions {
  static constexpr double kDefaultResolutionM = 0.02;
  static constexpr double kDefaultPoseToleranceM = 0.01;
  static constexpr double kDefaultPoseToleranceRad = 0.0175;  // ~1 degree
  static constexpr double kDefaultClampingMin = 0.001;
  static constexpr double kDefaultClampingMax = 0.999;
  static constexpr double kDefaultBeamPriorLengthM = 1.0;

  double resolution_m = kDefaultResolutionM;
  FusionRule rule = FusionRule::kIndependentOpinionPool;
  // render.resolution_m is overridden by resolution_m.
  RenderOptions render;
  // beam_grid.prior_reference_length_m is overridden by beam_prior_length_m.
  BeamGridOptions beam_grid;
  // Beam prior: a run of this length starts with occupancy 0.5 (p0 per cell follows).
  // Rendering measures evidence relative to this prior, so an untouched voxel is 0.5
  // whatever it is. A short length (one voxel) makes an untouched 7.5 m beam almost certain
  // to hold something (1 - 0.5^375 at 2 cm), and then a beam needs ~20 readings before any
  // free space shows; at 1 m one frame suffices, and the accuracy table improves (Brier
  // 0.0031 -> 0.0028 for the SR-3000, see docs/mapping.md).
  double beam_prior_length_m = kDefaultBeamPriorLengthM;
  double pose_tolerance_m = kDefaultPoseToleranceM;
  double pose_tolerance_rad = kDefaultPoseToleranceRad;
  // Fused probabilities are clamped to [min, max] (as OctoMap does) so the map
  // stays updatable.
  double clamping_min_probability = kDefaultClampingMin;
  double clamping_max_probability = kDefaultClampingMax;
  // Changed keys kept for ChangedKeysSince (oldest versions dropped first; the
  // newest version is always kept whole).
  std::size_t change_history_keys = std::size_t{1} << 24;
};

enum class MapStatus {
  kOk,
  kUnknownSensor,
  kDuplicateSensor,
  kInvalidPose,      // non-finite translation or a non-rotation matrix
  kInvalidArgument,  // e.g. null points with a non-zero count
};
[[nodiscard]] const char* MapStatusName(MapStatus status);

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
  std::size_t live_voxels = 0;
};

struct FuseStats {
  RenderStats render;
  std::size_t voxels_changed = 0;
};

class WorldMap {
 public:
  explicit WorldMap(const WorldMapOptions& options = {});
  ~WorldMap();
  WorldMap(const WorldMap&) = delete;
  WorldMap& operator=(const WorldMap&) = delete;

  [[nodiscard]] const WorldMapOptions& options() const { return options_; }
  [[nodiscard]] double resolution_m() const { return options_.resolution_m; }

  MapStatus AddSensor(const std::string& sensor_id, const SensorSpec& spec);
  [[nodiscard]] bool HasSensor(const std::string& sensor_id) const;
  [[nodiscard]] std::vector<std::string> SensorIds() const;

  // Applies one cloud (sensor frame, 3 floats per point; beyond_range as in
  // BeamGrid::Integrate) taken at T_world_sensor. If the pose left the
  // tolerance around the current period's pose, the period is committed first
  // (rendered if it has unrendered frames) and the beam grid restarts at the
  // new pose. Does not render: call Render.
  MapStatus Integrate(const std::string& sensor_id, const Eigen::Isometry3d& T_world_sensor,
                      const float* points_xyz, std::size_t point_count,
                      const std::vector<std::uint8_t>& beyond_range = {},
                      IntegrationStats* stats = nullptr, bool* committed = nullptr);
  // Renders the sensor's current period and replaces its previous live
  // contribution.
  MapStatus Render(const std::string& sensor_id, FuseStats* stats = nullptr);
  // Renders every sensor with unrendered frames.
  void RenderAll();
  // Folds the sensor's live contribution into the committed history and
  // restarts its beam grid (the next cloud starts a new period at its own
  // pose).
  MapStatus Commit(const std::string& sensor_id);

  // The fused map (world frame, log-odds per leaf). Voxels no sensor has
  // information about have no node, or a node at log-odds exactly 0 (p = 0.5)
  // once their last opinion went away.
  [[nodiscard]] const octomap::OcTree& tree() const { return *tree_; }
  // Incremented on every Render / Commit that changed the map.
  [[nodiscard]] std::uint64_t version() const { return version_; }
  // Keys whose fused value changed (including back to unknown) after `version`,
  // each once. std::nullopt if that version is older than the retained change
  // history (options.change_history_keys): the caller must resynchronise from
  // the whole tree.
  [[nodiscard]] std::optional<std::vector<octomap::OcTreeKey>> ChangedKeysSince(
      std::uint64_t version) const;
  [[nodiscard]] std::optional<SensorCounters> Counters(const std::string& sensor_id) const;
  [[nodiscard]] const BeamGrid* beam_grid(const std::string& sensor_id) const;
  // Fused occupancy of a world point; std::nullopt where the map has no
  // information (no node, or log-odds exactly 0).
  [[nodiscard]] std::optional<double> Occupancy(const Eigen::Vector3d& p_world) const;

 private:
  struct SensorState;
  [[nodiscard]] bool Moved(const SensorState& s, const Eigen::Isometry3d& T_world_sensor) const;
  // Recomputes the fused value of one key from committed history and live
  // grids.
  bool Refuse(const octomap::OcTreeKey& key);
  MapStatus CommitState(SensorState& s);
  void RenderState(SensorState& s, FuseStats* stats);

  WorldMapOptions options_;
  std::unique_ptr<octomap::OcTree> tree_;
  std::map<std::string, std::unique_ptr<SensorState>> sensors_;
  std::unordered_map<octomap::OcTreeKey, float, octomap::OcTreeKey::KeyHash> committed_;
  // Change log: keys changed by each version (ascending), bounded by
  // change_history_keys.
  struct Change {
    std::uint64_t version;
    std::vector<octomap::OcTreeKey> keys;
  };
  std::vector<Change> changes_;
  std::size_t change_log_keys_ = 0;
  std::uint64_t oldest_complete_version_ = 0;  // ChangedKeysSince(v) is exact for v >= this
  std::vector<octomap::OcTreeKey> pending_;    // keys changed by the version being built
  void PublishVersion();
  // Full-depth leaf of a key, created (value 0) if create; a cached
  // root-to-leaf path makes consecutive nearby keys cheap.
  octomap::OcTreeNode* FindLeaf(const octomap::OcTreeKey& key, bool create,
                                bool* created = nullptr);
  octomap::OcTreeNode* cursor_path_[17] = {};
  octomap::OcTreeKey cursor_key_;
  unsigned cursor_depth_ = 0;
  bool cursor_valid_ = false;
  std::uint64_t version_ = 0;
  float clamp_min_log_odds_;
  float clamp_max_log_odds_;
  std::vector<double> scratch_;
};

}  // namespace fusion
