#include "fusion/core/world_map.h"

#include <algorithm>
#include <cmath>

namespace fusion {
namespace {

bool ValidPose(const Eigen::Isometry3d& T) {
  if (!T.matrix().allFinite()) return false;
  const Eigen::Matrix3d R = T.linear();
  if ((R.transpose() * R - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff() > 1e-3) return false;
  return R.determinant() > 0.0;
}

}  // namespace

const char* MapStatusName(MapStatus status) {
  switch (status) {
    case MapStatus::kOk:
      return "ok";
    case MapStatus::kUnknownSensor:
      return "unknown sensor";
    case MapStatus::kDuplicateSensor:
      return "duplicate sensor";
    case MapStatus::kInvalidPose:
      return "invalid pose";
    case MapStatus::kInvalidArgument:
      return "invalid argument";
  }
  return "unknown status";
}

struct WorldMap::SensorState {
  SensorState(const SensorSpec& spec, const BeamGridOptions& grid_options,
              const RenderOptions& render)
      : grid(spec, grid_options), live(render.resolution_m, render.combine) {}
  BeamGrid grid;
  LocalGrid live;  // the rendered current period, empty after a commit
  Eigen::Isometry3d T_world_sensor = Eigen::Isometry3d::Identity();
  bool has_pose = false;
  bool dirty = false;  // frames integrated since the last render
  SensorCounters counters;
};

WorldMap::WorldMap(const WorldMapOptions& options) : options_(options) {
  options_.render.resolution_m = options_.resolution_m;
  options_.beam_grid.prior_reference_length_m = options_.beam_prior_length_m;
  tree_ = std::make_unique<octomap::OcTree>(options_.resolution_m);
  tree_->setClampingThresMin(options_.clamping_min_probability);
  tree_->setClampingThresMax(options_.clamping_max_probability);
  tree_->setOccupancyThres(0.5);
  clamp_min_log_odds_ = static_cast<float>(LogOdds(options_.clamping_min_probability));
  clamp_max_log_odds_ = static_cast<float>(LogOdds(options_.clamping_max_probability));
}

WorldMap::~WorldMap() = default;

MapStatus WorldMap::AddSensor(const std::string& sensor_id, const SensorSpec& spec) {
  if (sensors_.count(sensor_id) != 0) return MapStatus::kDuplicateSensor;
  sensors_[sensor_id] = std::make_unique<SensorState>(spec, options_.beam_grid, options_.render);
  return MapStatus::kOk;
}

bool WorldMap::HasSensor(const std::string& sensor_id) const {
  return sensors_.count(sensor_id) != 0;
}

std::vector<std::string> WorldMap::SensorIds() const {
  std::vector<std::string> ids;
  for (const auto& [id, state] : sensors_) ids.push_back(id);
  return ids;
}

bool WorldMap::Moved(const SensorState& s, const Eigen::Isometry3d& T_world_sensor) const {
  const double translation_m =
      (T_world_sensor.translation() - s.T_world_sensor.translation()).norm();
  const Eigen::AngleAxisd delta(s.T_world_sensor.linear().transpose() * T_world_sensor.linear());
  return translation_m > options_.pose_tolerance_m ||
         std::abs(delta.angle()) > options_.pose_tolerance_rad;
}

MapStatus WorldMap::Integrate(const std::string& sensor_id, const Eigen::Isometry3d& T_world_sensor,
                              const float* points_xyz, std::size_t point_count,
                              const std::vector<std::uint8_t>& beyond_range,
                              IntegrationStats* stats, bool* committed) {
  if (committed != nullptr) *committed = false;
  auto it = sensors_.find(sensor_id);
  if (it == sensors_.end()) return MapStatus::kUnknownSensor;
  if (!ValidPose(T_world_sensor)) return MapStatus::kInvalidPose;
  if (points_xyz == nullptr && point_count != 0) return MapStatus::kInvalidArgument;
  if (!beyond_range.empty() && beyond_range.size() != point_count) {
    return MapStatus::kInvalidArgument;
  }
  SensorState& s = *it->second;
  if (s.has_pose && Moved(s, T_world_sensor)) {
    CommitState(s);
    ++s.counters.pose_moves;
    if (committed != nullptr) *committed = true;
  }
  if (!s.has_pose || s.counters.frames_in_period == 0) {
    s.T_world_sensor = T_world_sensor;
    s.has_pose = true;
  }
  const IntegrationStats result = s.grid.Integrate(points_xyz, point_count, beyond_range);
  ++s.counters.frames_integrated;
  ++s.counters.frames_in_period;
  s.counters.points_updated += result.updated;
  s.counters.points_beyond_range += result.beyond_range;
  s.counters.points_missing += result.missing;
  s.counters.points_rejected += result.rejected_nonfinite + result.rejected_outside_fov;
  s.dirty = true;
  if (stats != nullptr) *stats = result;
  return MapStatus::kOk;
}

bool WorldMap::Refuse(const octomap::OcTreeKey& key) {
  // Opinions as log-odds: committed history first, then each sensor's live
  // period.
  scratch_.clear();
  const auto c = committed_.find(key);
  if (c != committed_.end()) scratch_.push_back(c->second);
  for (const auto& [id, state] : sensors_) {
    if (state->live.empty()) continue;
    if (const auto l = state->live.LogOddsOf(key)) scratch_.push_back(*l);
  }
  if (scratch_.empty()) {
    // No opinion left: back to unknown. The node is kept at log-odds 0 (p =
    // 0.5) rather than deleted: OctoMap 1.9's deleteNode frees an emptied inner
    // node without its child array (an assertion in its node destructor).
    octomap::OcTreeNode* node = FindLeaf(key, /*create=*/false);
    if (node == nullptr || node->getLogOdds() == 0.0f) return false;
    node->setLogOdds(0.0f);
    pending_.push_back(key);
    return true;
  }
  double fused_log_odds = 0.0;
  switch (options_.rule) {
    case FusionRule::kIndependentOpinionPool:
      for (double l : scratch_) fused_log_odds += l;
      break;
    case FusionRule::kMax:
      fused_log_odds = *std::max_element(scratch_.begin(), scratch_.end());
      break;
    case FusionRule::kDeMorgan: {
      double free = 1.0;
      for (double l : scratch_) free *= 1.0 - ProbabilityFromLogOdds(l);
      fused_log_odds = LogOdds(std::clamp(1.0 - free, 1e-12, 1.0 - 1e-12));
      break;
    }
  }
  const float value =
      std::clamp(static_cast<float>(fused_log_odds), clamp_min_log_odds_, clamp_max_log_odds_);
  bool created = false;
  octomap::OcTreeNode* node = FindLeaf(key, /*create=*/true, &created);
  if (!created && node->getLogOdds() == value) return false;
  // Inner nodes are refreshed by updateInnerOccupancy() when the version is
  // published.
  node->setLogOdds(value);
  pending_.push_back(key);
  return true;
}

octomap::OcTreeNode* WorldMap::FindLeaf(const octomap::OcTreeKey& key, bool create, bool* created) {
  // The map's tree is never pruned (lazy updates, and no one else can prune a
  // tree we only hand out const), so every leaf lives at full depth. The walk
  // restarts from the deepest node it shares with the previous key (keys arrive
  // in brick order).
  constexpr unsigned kDepth = 16;
  if (created != nullptr) *created = false;
  octomap::OcTreeNode* root = tree_->getRoot();
  if (root == nullptr) {
    if (!create) return nullptr;
    tree_->setNodeValue(key, 0.0f, /*lazy_eval=*/true);
    cursor_valid_ = false;
    if (created != nullptr) *created = true;
    return tree_->search(key);
  }
  unsigned depth = 0;
  if (cursor_valid_) {
    const unsigned diff =
        static_cast<unsigned>((cursor_key_.k[0] ^ key.k[0]) | (cursor_key_.k[1] ^ key.k[1]) |
                              (cursor_key_.k[2] ^ key.k[2]));
    // Number of equal leading bits = depth of the deepest shared node.
    depth = diff == 0 ? kDepth : static_cast<unsigned>(__builtin_clz(diff)) - 16u;
    depth = std::min(depth, cursor_depth_);
  } else {
    cursor_path_[0] = root;
    cursor_depth_ = 0;
  }
  octomap::OcTreeNode* node = cursor_path_[depth];
  cursor_key_ = key;
  cursor_valid_ = true;
  for (; depth < kDepth; ++depth) {
    const unsigned child = octomap::computeChildIdx(key, static_cast<int>(kDepth - 1 - depth));
    if (!tree_->nodeChildExists(node, child)) {
      if (!create) {
        cursor_depth_ = depth;
        return nullptr;
      }
      node = tree_->createNodeChild(node, child);
      if (created != nullptr) *created = true;
    } else {
      node = tree_->getNodeChild(node, child);
    }
    cursor_path_[depth + 1] = node;
  }
  cursor_depth_ = kDepth;
  return node;
}

void WorldMap::RenderState(SensorState& s, FuseStats* stats) {
  FuseStats result;
  LocalGrid rendered = RenderBeamGrid(s.grid, s.T_world_sensor, options_.render, &result.render);
  LocalGrid old = std::move(s.live);
  s.live = std::move(rendered);
  std::size_t changed = 0;
  // Only keys whose opinion from this sensor changed (appeared, went away or took
  // another value) can change the fused value: the committed history and the
  // other sensors' opinions are what they were.
  old.ForEachLogOdds([&](const octomap::OcTreeKey& key, float) {
    if (!s.live.LogOddsOf(key)) changed += Refuse(key) ? 1 : 0;
  });
  s.live.ForEachLogOdds([&](const octomap::OcTreeKey& key, float l) {
    const auto before = old.LogOddsOf(key);
    if (!before || static_cast<float>(*before) != l) changed += Refuse(key) ? 1 : 0;
  });
  if (changed > 0) PublishVersion();
  s.dirty = false;
  ++s.counters.renders;
  s.counters.live_voxels = s.live.size();
  result.voxels_changed = changed;
  if (stats != nullptr) *stats = result;
}

MapStatus WorldMap::Render(const std::string& sensor_id, FuseStats* stats) {
  auto it = sensors_.find(sensor_id);
  if (it == sensors_.end()) return MapStatus::kUnknownSensor;
  RenderState(*it->second, stats);
  return MapStatus::kOk;
}

void WorldMap::RenderAll() {
  for (auto& [id, state] : sensors_) {
    if (state->dirty) RenderState(*state, nullptr);
  }
}

MapStatus WorldMap::CommitState(SensorState& s) {
  if (s.dirty) RenderState(s, nullptr);
  LocalGrid live = std::move(s.live);
  s.live = LocalGrid(options_.resolution_m, options_.render.combine);
  live.ForEachLogOdds([&](const octomap::OcTreeKey& key, float l) {
    auto [it, inserted] = committed_.try_emplace(key, l);
    if (!inserted) {
      double fused = 0.0;
      switch (options_.rule) {
        case FusionRule::kIndependentOpinionPool:
          fused = static_cast<double>(it->second) + l;
          break;
        case FusionRule::kMax:
          fused = std::max<double>(it->second, l);
          break;
        case FusionRule::kDeMorgan:
          fused = LogOdds(std::clamp(
              FuseDeMorgan(ProbabilityFromLogOdds(it->second), ProbabilityFromLogOdds(l)), 1e-12,
              1.0 - 1e-12));
          break;
      }
      it->second = static_cast<float>(fused);
    }
    it->second = std::clamp(it->second, clamp_min_log_odds_, clamp_max_log_odds_);
  });
  std::size_t changed = 0;
  live.ForEachLogOdds(
      [&](const octomap::OcTreeKey& key, float) { changed += Refuse(key) ? 1 : 0; });
  if (changed > 0) PublishVersion();
  s.grid.Reset();
  s.dirty = false;
  s.counters.frames_in_period = 0;
  s.counters.live_voxels = 0;
  ++s.counters.commits;
  return MapStatus::kOk;
}

MapStatus WorldMap::Commit(const std::string& sensor_id) {
  auto it = sensors_.find(sensor_id);
  if (it == sensors_.end()) return MapStatus::kUnknownSensor;
  return CommitState(*it->second);
}

void WorldMap::PublishVersion() {
  tree_->updateInnerOccupancy();
  ++version_;
  change_log_keys_ += pending_.size();
  changes_.push_back({version_, std::move(pending_)});
  pending_.clear();
  while (changes_.size() > 1 && change_log_keys_ > options_.change_history_keys) {
    change_log_keys_ -= changes_.front().keys.size();
    oldest_complete_version_ = changes_.front().version;
    changes_.erase(changes_.begin());
  }
}

std::optional<std::vector<octomap::OcTreeKey>> WorldMap::ChangedKeysSince(
    std::uint64_t version) const {
  if (version < oldest_complete_version_) return std::nullopt;
  std::vector<octomap::OcTreeKey> keys;
  std::size_t versions = 0;
  for (const Change& change : changes_) {
    if (change.version > version) {
      keys.insert(keys.end(), change.keys.begin(), change.keys.end());
      ++versions;
    }
  }
  // One version lists each key once (a render or commit re-fuses every key at most once).
  if (versions <= 1) return keys;
  std::sort(keys.begin(), keys.end(), [](const octomap::OcTreeKey& a, const octomap::OcTreeKey& b) {
    return std::lexicographical_compare(a.k, a.k + 3, b.k, b.k + 3);
  });
  keys.erase(std::unique(keys.begin(), keys.end()), keys.end());
  return keys;
}

std::optional<SensorCounters> WorldMap::Counters(const std::string& sensor_id) const {
  auto it = sensors_.find(sensor_id);
  if (it == sensors_.end()) return std::nullopt;
  return it->second->counters;
}

const BeamGrid* WorldMap::beam_grid(const std::string& sensor_id) const {
  auto it = sensors_.find(sensor_id);
  if (it == sensors_.end()) return nullptr;
  return &it->second->grid;
}

std::optional<double> WorldMap::Occupancy(const Eigen::Vector3d& p_world) const {
  const octomap::OcTreeNode* node = tree_->search(p_world.x(), p_world.y(), p_world.z());
  if (node == nullptr || node->getLogOdds() == 0.0f) return std::nullopt;
  return node->getOccupancy();
}

}  // namespace fusion
