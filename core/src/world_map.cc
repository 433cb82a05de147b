#include "fusion/core/world_map.h"

#include <algorithm>
#include <cmath>
#include <string>
#include <utility>

#include "fusion/core/octree_merge.h"
#include "fusion/core/projective_render.h"

namespace fusion {
namespace {

std::unique_ptr<octomap::OcTree> NewTree(const WorldMapOptions& options) {
  auto tree = std::make_unique<octomap::OcTree>(options.resolution_m);
  tree->setClampingThresMin(options.clamping_min_probability);
  tree->setClampingThresMax(options.clamping_max_probability);
  tree->setOccupancyThres(options.occupancy_threshold);
  return tree;
}

// count += delta (a merge's report of the leaves it added, negative when it removed some).
void AddLeaves(std::size_t* count, std::int64_t delta) {
  *count = static_cast<std::size_t>(static_cast<std::int64_t>(*count) + delta);
}

// A driver covering the whole key space.
RenderedGrid Everything(double resolution_m) {
  RenderedGrid all(resolution_m);
  all.Append({0, 0.0f, 0});
  return all;
}

}  // namespace

BeamGridOptions SensorGridOptions(const WorldMapOptions& options) {
  BeamGridOptions grid = options.beam_grid;
  grid.prior_reference_length_m = options.beam_prior_length_m;
  return grid;
}

BeamGridOptions SensorGridOptions(const WorldMapOptions& options, const SensorSpec& spec) {
  BeamGridOptions grid = SensorGridOptions(options);
  if (spec.beam_prior_length_m > 0.0) grid.prior_reference_length_m = spec.beam_prior_length_m;
  return grid;
}

RenderOptions MapRenderOptions(const WorldMapOptions& options) {
  RenderOptions render = options.render;
  render.resolution_m = options.resolution_m;
  return render;
}

bool WorldMapOptions::IsValid(std::string* why) const {
  std::string local;
  std::string& out = why != nullptr ? *why : local;
  const auto fail = [&out](const char* message) {
    out = message;
    return false;
  };
  if (!(resolution_m >= RenderOptions::kMinResolutionM &&
        resolution_m <= RenderOptions::kMaxResolutionM)) {
    return fail("resolution_m must lie in [0.001, 10] m");
  }
  if (!(pose_tolerance_m >= 0.0 && std::isfinite(pose_tolerance_m))) {
    return fail("pose_tolerance_m must be finite and >= 0");
  }
  if (!(pose_tolerance_rad >= 0.0 && pose_tolerance_rad <= 3.14159265358979323846)) {
    return fail("pose_tolerance_rad must lie in [0, pi]");
  }
  if (!(clamping_min_probability > 0.0 && clamping_min_probability < clamping_max_probability &&
        clamping_max_probability < 1.0)) {
    return fail(
        "clamping_min_probability and clamping_max_probability must satisfy 0 < min < "
        "max < 1");
  }
  if (!(history_clamping_max_probability > clamping_min_probability &&
        history_clamping_max_probability <= clamping_max_probability)) {
    return fail(
        "history_clamping_max_probability must lie in (clamping_min_probability, "
        "clamping_max_probability]");
  }
  if (!(forget_half_life_s >= 0.0 && std::isfinite(forget_half_life_s))) {
    return fail("forget_half_life_s must be finite and >= 0 (0: never forget)");
  }
  if (!(occupancy_threshold > 0.0 && occupancy_threshold < 1.0)) {
    return fail("occupancy_threshold must lie in (0, 1)");
  }
  if (!(beam_prior_length_m > 0.0 && beam_prior_length_m <= 1000.0)) {
    return fail("beam_prior_length_m must lie in (0, 1000] m");
  }
  if (!SensorGridOptions(*this).IsValid(&out)) {
    out = "beam_grid." + out;
    return false;
  }
  if (!MapRenderOptions(*this).IsValid(&out)) {
    out = "render." + out;
    return false;
  }
  return true;
}

struct WorldMap::SensorState {
  SensorSpec spec;
  std::unique_ptr<SensorPeriods> periods;  // created by the first Integrate / Render / Commit
  RenderedGrid live;                       // the rendered open period; empty after a commit
  std::uint64_t rendered_frames = 0;       // frames of the open period that `live` holds
  SensorCounters counters;
};

WorldMap::WorldMap(const WorldMapOptions& options)
    : options_(options),
      policy_(FusionPolicy::Make(options.rule, options.clamping_min_probability,
                                 options.clamping_max_probability)),
      history_policy_(FusionPolicy::Make(options.rule, options.clamping_min_probability,
                                         options.history_clamping_max_probability)),
      render_(MapRenderOptions(options)),
      committed_(NewTree(options)),
      published_(NewTree(options)) {
  last_.tree = published_;
}

WorldMap::~WorldMap() = default;

MapStatus WorldMap::AddSensor(const std::string& sensor_id, const SensorSpec& spec) {
  if (sensors_.count(sensor_id) != 0) return MapStatus::kDuplicateSensor;
  auto state = std::make_unique<SensorState>();
  state->spec = spec;
  state->live = RenderedGrid(options_.resolution_m);
  sensors_[sensor_id] = std::move(state);
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

WorldMap::SensorState* WorldMap::Find(const std::string& sensor_id) {
  auto it = sensors_.find(sensor_id);
  return it == sensors_.end() ? nullptr : it->second.get();
}

const WorldMap::SensorState* WorldMap::Find(const std::string& sensor_id) const {
  auto it = sensors_.find(sensor_id);
  return it == sensors_.end() ? nullptr : it->second.get();
}

octomap::OcTree& WorldMap::Working(CatchUp* catch_up) {
  if (working_) return *working_;
  if (spare_ && spare_.use_count() == 1) {
    if (catch_up != nullptr) {
      *catch_up = {published_.get(), &spare_lag_, &copy_driver_};  // the caller's merge does it
    } else {
      std::int64_t added = 0;
      CopyRegions(*spare_, *published_, spare_lag_, &copy_driver_, &added);
      AddLeaves(&spare_leaves_, added);
      spare_lag_.clear();
    }
    working_ = std::move(spare_);
    working_leaves_ = spare_leaves_;
  } else {
    if (spare_) ++tree_copies_;
    working_ = std::make_shared<octomap::OcTree>(*published_);
    working_leaves_ = published_leaves_;
    spare_lag_.clear();
  }
  spare_.reset();
  return *working_;
}

std::size_t WorldMap::FuseIntoWorking(const std::vector<const RenderedGrid*>& drivers) {
  CatchUp catch_up;
  octomap::OcTree& target = Working(&catch_up);
  const std::size_t before = pending_.size();
  std::int64_t added = 0;
  try {
    FuseRegions(target, policy_, Sources(nullptr), drivers, &pending_, &catch_up, &added);
  } catch (...) {
    // Too many inputs are refused before anything is written; whatever else stopped the walk,
    // the lagging regions are brought to the published tree the plain way.
    if (catch_up.reference != nullptr) CopyRegions(target, *catch_up.reference, spare_lag_);
    spare_lag_.clear();
    working_leaves_ = target.getNumLeafNodes();
    throw;
  }
  AddLeaves(&working_leaves_, added);
  spare_lag_.clear();
  MergeRun(before);
  return pending_.size() - before;
}

std::vector<MergeSource> WorldMap::Sources(const SensorState* except) const {
  std::vector<MergeSource> sources{{committed_.get(), nullptr}};
  for (const auto& [id, s] : sensors_) {
    if (s.get() != except && !s->live.empty()) sources.push_back({nullptr, &s->live});
  }
  return sources;
}

MapStatus WorldMap::ReplaceLive(const std::string& sensor_id, RenderedGrid rendered,
                                FuseStats* stats) {
  SensorState* s = Find(sensor_id);
  if (s == nullptr) return MapStatus::kUnknownSensor;
  RenderedGrid old = std::move(s->live);
  s->live = std::move(rendered);
  const std::size_t changed = FuseIntoWorking({&old, &s->live});
  render_scratch_.Recycle(std::move(old));
  s->counters.live_nodes = s->live.size();
  if (stats != nullptr) stats->regions_changed = changed;
  return MapStatus::kOk;
}

SaturatedFree WorldMap::Saturation(const std::string& sensor_id) const {
  SaturatedFree saturated;
  // Eq. 16 only: under max or De Morgan a free value above the clamp still moves the map.
  if (options_.rule != FusionRule::kIndependentOpinionPool) return saturated;
  saturated.history = committed_.get();
  saturated.clamp_min_log_odds = policy_.clamp_min_log_odds;
  for (const auto& [id, s] : sensors_) {
    if (id != sensor_id && !s->live.empty()) saturated.others.push_back(&s->live);
  }
  return saturated;
}

MapStatus WorldMap::CommitLive(const std::string& sensor_id) {
  SensorState* s = Find(sensor_id);
  if (s == nullptr) return MapStatus::kUnknownSensor;
  if (s->live.empty()) return MapStatus::kOk;
  std::int64_t added = 0;
  FuseRegions(*committed_, history_policy_, {{committed_.get(), nullptr}, {nullptr, &s->live}},
              {&s->live}, nullptr, nullptr, &added);
  AddLeaves(&committed_leaves_, added);
  RenderedGrid old = std::move(s->live);
  s->live = RenderedGrid(options_.resolution_m);
  s->counters.live_nodes = 0;
  struct GiveBack {  // every return below hands old's memory to the next render
    RenderScratch& scratch;
    RenderedGrid& grid;
    ~GiveBack() { scratch.Recycle(std::move(grid)); }
  } give_back{render_scratch_, old};
  // Where no other live contribution overlaps, the map already holds what the history now
  // holds (both are Fuse(history before, this contribution)) except where the history's
  // tighter occupied clamp cut it: there the contribution was positive, since the history
  // never holds more than its clamp.
  const RenderedGrid* refuse = &old;
  RenderedGrid positive(options_.resolution_m);
  if (Sources(nullptr).size() == 1) {
    if (history_policy_.clamp_max_log_odds >= policy_.clamp_max_log_odds) return MapStatus::kOk;
    for (const MapNode& node : old.nodes()) {
      if (node.log_odds > 0.0f) positive.Append(node);
    }
    if (positive.empty()) return MapStatus::kOk;
    refuse = &positive;
  }
  (void)FuseIntoWorking({refuse});
  return MapStatus::kOk;
}

void WorldMap::LoadHistory(const octomap::OcTree& history) {
  Reset();
  const RenderedGrid all = Everything(options_.resolution_m);
  std::int64_t added = 0;
  FuseRegions(*committed_, history_policy_, {{&history, nullptr}}, {&all}, nullptr, nullptr,
              &added);
  AddLeaves(&committed_leaves_, added);
  working_ = std::make_shared<octomap::OcTree>(*committed_);
  working_leaves_ = committed_leaves_;
}

void WorldMap::Reset() {
  committed_ = NewTree(options_);
  working_ = NewTree(options_);
  committed_leaves_ = working_leaves_ = 0;
  spare_.reset();
  spare_lag_.clear();
  pending_.clear();
  pending_reset_ = true;
  for (auto& [id, s] : sensors_) {
    s->live = RenderedGrid(options_.resolution_m);
    s->rendered_frames = 0;
    s->counters.frames_in_period = 0;
    s->counters.live_nodes = 0;
    if (s->periods) s->periods->Reset();
  }
}

std::uint64_t WorldMap::ClearBox(const Eigen::AlignedBox3d& box_world) {
  for (const auto& [id, s] : sensors_) {
    (void)CommitLive(id);
    s->rendered_frames = 0;
    s->counters.frames_in_period = 0;
    if (s->periods) s->periods->Reset();
  }
  // The history and the map hold the same now; both guide the cover, to miss nothing.
  std::vector<MapRegion> regions = RegionsInBox(*committed_, box_world);
  for (const MapRegion& r : RegionsInBox(Working(), box_world)) regions.push_back(r);
  NormaliseRegions(&regions);
  if (regions.empty()) return 0;
  std::uint64_t voxels = 0;
  for (const MapRegion& r : regions) {
    ForEachInRegion(Working(), r, [&voxels](const octomap::OcTreeKey&, unsigned depth,
                                            const octomap::OcTreeNode* node) {
      if (node != nullptr) voxels += MortonSpan(depth);
    });
  }
  std::int64_t added = 0;
  CopyRegions(*committed_, octomap::OcTree(options_.resolution_m), regions, nullptr, &added);
  AddLeaves(&committed_leaves_, added);
  RenderedGrid drivers(options_.resolution_m);
  for (const MapRegion& r : regions) drivers.Append({r.code, 0.0f, r.depth});
  (void)FuseIntoWorking({&drivers});
  return voxels;
}

std::uint64_t WorldMap::Forget(double elapsed_s) {
  if (!(options_.forget_half_life_s > 0.0) || !(elapsed_s > 0.0)) return 0;
  const auto factor = static_cast<float>(std::exp2(-elapsed_s / options_.forget_half_life_s));
  // Scaling every node (inner ones hold the maximum of their children) keeps the tree's
  // invariants: the maximum of scaled values is the scaled maximum, equal siblings stay equal.
  for (auto it = committed_->begin_tree(); it != committed_->end_tree(); ++it) {
    it->setLogOdds(it->getLogOdds() * factor);
  }
  RenderedGrid forgotten(options_.resolution_m);
  ForEachInRegion(
      *committed_, {0, 0},
      [&forgotten](const octomap::OcTreeKey& key, unsigned depth, const octomap::OcTreeNode* node) {
        if (node != nullptr && std::abs(node->getLogOdds()) < WorldMapOptions::kForgottenLogOdds) {
          forgotten.Append(
              {MortonAtDepth(MortonOf(key), depth), 0.0f, static_cast<std::uint8_t>(depth)});
        }
      });
  if (!forgotten.empty()) {
    std::int64_t added = 0;
    FuseRegions(*committed_, history_policy_, {}, {&forgotten}, nullptr, nullptr, &added);
    AddLeaves(&committed_leaves_, added);
  }
  const RenderedGrid all = Everything(options_.resolution_m);
  (void)FuseIntoWorking({&all});
  return forgotten.size();
}

void WorldMap::MergeRun(std::size_t run_begin) {
  // Each merge reports its regions in order: keep the version's list one ordered run.
  const auto before = [](const MapRegion& a, const MapRegion& b) {
    return a.code != b.code ? a.code < b.code : a.depth < b.depth;
  };
  if (run_begin == 0 || run_begin == pending_.size()) return;  // one run already
  std::inplace_merge(pending_.begin(), pending_.begin() + static_cast<std::ptrdiff_t>(run_begin),
                     pending_.end(), before);
}

Publication WorldMap::Publish() {
  if (!working_ || (pending_.empty() && !pending_reset_)) return last_;
  MapChanges changes;
  changes.version = ++version_;
  changes.reset = pending_reset_;
  // A copy of the exact size: pending_ keeps its memory for the next version's changes (grown
  // afresh, a moving sensor's ~100 k regions a frame came from newly mapped pages each time).
  changes.regions.assign(pending_.begin(), pending_.end());
  NormaliseRegions(&changes.regions);
  pending_.clear();
  pending_reset_ = false;
  // The tree published before becomes the spare: it lacks just this version's changes (after a
  // reset it lacks everything, and is not kept).
  spare_ = changes.reset ? nullptr : std::move(published_);
  spare_leaves_ = published_leaves_;
  spare_lag_ = changes.reset ? std::vector<MapRegion>{} : changes.regions;
  published_ = std::move(working_);
  published_leaves_ = working_leaves_;
  last_.tree = published_;
  last_.leaves = published_leaves_;
  last_.changes = std::move(changes);
  return last_;
}

MapStatus WorldMap::Integrate(const std::string& sensor_id, const Eigen::Isometry3d& T_world_sensor,
                              const float* points_xyz, std::size_t point_count,
                              const std::vector<std::uint8_t>& beyond_range,
                              IntegrationStats* stats, bool* committed) {
  if (committed != nullptr) *committed = false;
  SensorState* s = Find(sensor_id);
  if (s == nullptr) return MapStatus::kUnknownSensor;
  if (!s->periods) {
    s->periods = std::make_unique<SensorPeriods>(
        s->spec, SensorGridOptions(options_, s->spec), options_.pose_tolerance_m,
        options_.pose_tolerance_rad, options_.resolution_m);
  }
  PeriodIntegration result;
  std::unique_ptr<Period> sealed;
  const MapStatus status = s->periods->Integrate(T_world_sensor, points_xyz, point_count,
                                                 beyond_range, /*may_seal=*/true, &result, &sealed);
  if (status != MapStatus::kOk) return status;
  if (sealed) {
    if (s->rendered_frames != sealed->frames) {
      RenderStats render_stats;
      const SaturatedFree skip = Saturation(sensor_id);
      (void)ReplaceLive(sensor_id, fusion::Render(*sealed->grid, sealed->T_world_sensor, render_,
                                                  &render_stats, &skip, &render_scratch_));
      ++s->counters.renders;
    }
    (void)CommitLive(sensor_id);
    (void)Publish();
    s->periods->Recycle(std::move(sealed));
    s->rendered_frames = 0;
    s->counters.frames_in_period = 0;
    ++s->counters.commits;
    ++s->counters.pose_moves;
    if (committed != nullptr) *committed = true;
  }
  ++s->counters.frames_integrated;
  ++s->counters.frames_in_period;
  s->counters.points_updated += result.stats.updated;
  s->counters.points_beyond_range += result.stats.beyond_range;
  s->counters.points_missing += result.stats.missing;
  s->counters.points_rejected += result.stats.rejected_nonfinite +
                                 result.stats.rejected_outside_fov +
                                 result.stats.rejected_outside_map;
  if (stats != nullptr) *stats = result.stats;
  return MapStatus::kOk;
}

MapStatus WorldMap::Render(const std::string& sensor_id, FuseStats* stats) {
  SensorState* s = Find(sensor_id);
  if (s == nullptr) return MapStatus::kUnknownSensor;
  FuseStats result;
  if (s->periods && s->periods->open().frames > 0) {
    const Period& open = s->periods->open();
    const SaturatedFree skip = Saturation(sensor_id);
    (void)ReplaceLive(
        sensor_id,
        fusion::Render(*open.grid, open.T_world_sensor, render_, &result.render, &skip,
                       &render_scratch_),
        &result);
    s->rendered_frames = open.frames;
    (void)Publish();
  }
  ++s->counters.renders;
  if (stats != nullptr) *stats = result;
  return MapStatus::kOk;
}

void WorldMap::RenderAll() {
  for (auto& [id, s] : sensors_) {
    if (s->periods && s->periods->open().frames > s->rendered_frames) (void)Render(id);
  }
}

MapStatus WorldMap::Commit(const std::string& sensor_id) {
  SensorState* s = Find(sensor_id);
  if (s == nullptr) return MapStatus::kUnknownSensor;
  if (s->periods && s->periods->open().frames > s->rendered_frames) (void)Render(sensor_id);
  (void)CommitLive(sensor_id);
  if (s->periods) s->periods->Reset();
  s->rendered_frames = 0;
  s->counters.frames_in_period = 0;
  ++s->counters.commits;
  (void)Publish();
  return MapStatus::kOk;
}

const octomap::OcTree& WorldMap::tree() const { return working_ ? *working_ : *published_; }

std::optional<SensorCounters> WorldMap::Counters(const std::string& sensor_id) const {
  const SensorState* s = Find(sensor_id);
  if (s == nullptr) return std::nullopt;
  return s->counters;
}

const BeamGrid* WorldMap::beam_grid(const std::string& sensor_id) const {
  const SensorState* s = Find(sensor_id);
  if (s == nullptr || !s->periods) return nullptr;
  return s->periods->open().grid.get();
}

std::optional<double> WorldMap::Occupancy(const Eigen::Vector3d& p_world) const {
  const octomap::OcTreeNode* node = tree().search(p_world.x(), p_world.y(), p_world.z());
  if (node == nullptr) return std::nullopt;
  return node->getOccupancy();
}

std::size_t WorldMap::MemoryBytes() const {
  std::size_t bytes = TreeMemoryBytes(*committed_, committed_leaves_) +
                      TreeMemoryBytes(*published_, published_leaves_);
  if (working_) bytes += TreeMemoryBytes(*working_, working_leaves_);
  if (spare_) bytes += TreeMemoryBytes(*spare_, spare_leaves_);
  for (const auto& [id, s] : sensors_) bytes += s->live.MemoryBytes();
  return bytes + render_scratch_.MemoryBytes() + copy_driver_.MemoryBytes() +
         (pending_.capacity() + spare_lag_.capacity()) * sizeof(MapRegion);
}

}  // namespace fusion
