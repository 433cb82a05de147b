#include "fusion/service/fusion_worker.h"

#include <spdlog/spdlog.h>
#include <sys/resource.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>

#include "fusion/core/octree_edit.h"

namespace fusion::service {
namespace {

// Above this many changed voxels a render updates the published map's inner nodes in one pass.
constexpr std::size_t kLazyUpdateKeys = 4096;

}  // namespace

FusionWorker::FusionWorker(WorkerOptions options, std::vector<SensorSetup> sensors,
                           IngestQueues* queues, SnapshotHub* hub)
    : options_(std::move(options)), sensors_(std::move(sensors)), queues_(queues), hub_(hub) {}

FusionWorker::~FusionWorker() { Stop(); }

bool FusionWorker::Start(std::unique_ptr<octomap::OcTree> base, std::string* error) {
  std::lock_guard<std::mutex> lock(map_mutex_);
  base_ = std::move(base);
  RebuildMapLocked();
  for (const auto& sensor : sensors_) {
    const MapStatus status = map_->AddSensor(sensor.id, sensor.spec);
    if (status != MapStatus::kOk) {
      *error = "sensor '" + sensor.id + "': " + MapStatusName(status);
      return false;
    }
  }
  if (base_) {
    version_offset_ = 1;
    PublishLocked({}, /*reset=*/true);
  }
  thread_ = std::thread([this] { Loop(); });
  return true;
}

void FusionWorker::Stop() {
  if (!thread_.joinable()) return;
  stop_ = true;
  queues_->Wake();
  thread_.join();
}

void FusionWorker::RebuildMapLocked() {
  map_ = std::make_unique<WorldMap>(options_.map);
  RebuildPublishedLocked();
  rendered_map_version_ = 0;
  dirty_ = false;
}

void FusionWorker::Loop() {
  // Queries come first: the worker (and the render threads it starts, which inherit this) runs
  // at a lower priority than the gRPC and DDS threads, so a render never holds a query back
  // for a whole time slice on a busy machine. Linux keeps a nice value per thread.
  if (options_.nice > 0 &&
      setpriority(PRIO_PROCESS, static_cast<id_t>(syscall(SYS_gettid)), options_.nice) != 0) {
    spdlog::warn("worker: could not lower its priority: {}", std::strerror(errno));
  }
  using Clock = std::chrono::steady_clock;
  auto last_render = Clock::now();
  std::vector<Cloud> clouds;
  const auto step = [&](Clock::time_point until) {
    clouds.clear();
    queues_->PopAll(&clouds, until);
    std::lock_guard<std::mutex> lock(map_mutex_);
    for (const Cloud& cloud : clouds) IntegrateLocked(cloud);
    const auto now = Clock::now();
    if (dirty_ && (now - last_render >= options_.render_interval || stop_)) {
      // The cadence counts from the start of a render: a render that takes most of the
      // interval is followed by the next one as soon as the interval is over.
      last_render = now;
      RenderAndPublishLocked();
    }
  };
  while (!stop_) {
    bool dirty = false;
    {
      std::lock_guard<std::mutex> lock(map_mutex_);
      dirty = dirty_;
    }
    step(dirty ? last_render + options_.render_interval
               : Clock::now() + std::chrono::milliseconds(500));
  }
  step(Clock::now());  // drain what is left, render and publish
}

void FusionWorker::IntegrateLocked(const Cloud& cloud) {
  auto* counters = queues_->counters(cloud.sensor_id);
  const SensorSetup* setup = nullptr;
  for (const auto& s : sensors_) {
    if (s.id == cloud.sensor_id) setup = &s;
  }
  if (counters == nullptr || setup == nullptr) return;
  const Eigen::Isometry3d T_world_sensor = cloud.T_world_published * setup->T_published_sensor;
  IntegrationStats stats;
  MapStatus status = MapStatus::kInvalidArgument;
  try {
    status = map_->Integrate(cloud.sensor_id, T_world_sensor, cloud.xyz.data(),
                             cloud.xyz.size() / 3, cloud.beyond_range, &stats);
  } catch (const std::exception& e) {
    spdlog::error("worker: cloud {} of '{}' failed: {}", cloud.sequence_number, cloud.sensor_id,
                  e.what());
    return;
  }
  if (status != MapStatus::kOk) {
    spdlog::warn("worker: cloud {} of '{}' not integrated: {}", cloud.sequence_number,
                 cloud.sensor_id, MapStatusName(status));
    return;
  }
  dirty_ = true;
  integrated_.fetch_add(1, std::memory_order_relaxed);
  counters->integrated.fetch_add(1, std::memory_order_relaxed);
  counters->points_updated.fetch_add(stats.updated, std::memory_order_relaxed);
  counters->points_beyond_range.fetch_add(stats.beyond_range, std::memory_order_relaxed);
  counters->points_missing.fetch_add(stats.missing, std::memory_order_relaxed);
  counters->points_rejected.fetch_add(stats.rejected_nonfinite + stats.rejected_outside_fov,
                                      std::memory_order_relaxed);
  spdlog::debug("worker: cloud {} of '{}': {} updated, {} beyond range, {} missing",
                cloud.sequence_number, cloud.sensor_id, stats.updated, stats.beyond_range,
                stats.missing);
}

std::optional<float> FusionWorker::FusedLogOddsLocked(const octomap::OcTreeKey& key) const {
  const octomap::OcTreeNode* live = map_->tree().search(key);
  // A node at log-odds exactly 0 is a voxel whose last opinion went away: no information.
  if (live != nullptr && live->getLogOdds() == 0.0f) live = nullptr;
  const octomap::OcTreeNode* base = base_ ? base_->search(key) : nullptr;
  if (live == nullptr && base == nullptr) return std::nullopt;
  if (base == nullptr) return live->getLogOdds();
  if (live == nullptr) return base->getLogOdds();
  const double p = Fuse(options_.map.rule, base->getOccupancy(), live->getOccupancy());
  const double clamped =
      std::clamp(p, options_.map.clamping_min_probability, options_.map.clamping_max_probability);
  return static_cast<float>(LogOdds(clamped));
}

void FusionWorker::RenderAndPublishLocked() {
  const auto start = std::chrono::steady_clock::now();
  try {
    map_->RenderAll();
  } catch (const std::exception& e) {
    spdlog::error("worker: render failed: {}", e.what());
    return;
  }
  dirty_ = false;
  const auto rendered = std::chrono::steady_clock::now();
  const std::uint64_t integrated = integrated_.load();
  auto since = map_->ChangedKeysSince(rendered_map_version_);
  std::vector<octomap::OcTreeKey> changed;
  const bool full_refresh = !since;
  if (since) changed = std::move(*since);
  rendered_map_version_ = map_->version();
  if (full_refresh) {
    spdlog::warn("worker: change history exhausted; rebuilding the map");
    RebuildPublishedLocked();
  } else {
    // Many changes (a first render, a new sensor pose): set the leaves alone and refresh the
    // inner nodes in one pass at the end, instead of along every leaf's path.
    const bool lazy = changed.size() > kLazyUpdateKeys;
    for (const auto& key : changed) {
      // Voxels that lost their information disappear from the published map.
      if (const auto value = FusedLogOddsLocked(key)) {
        published_->setNodeValue(key, *value, lazy);
      } else {
        (void)DeleteVoxel(*published_, key);
      }
    }
    if (lazy) {
      published_->updateInnerOccupancy();
      published_->prune();  // as setNodeValue would have, leaf by leaf
    }
  }
  for (const auto& sensor : sensors_) {
    if (const BeamGrid* grid = map_->beam_grid(sensor.id)) {
      queues_->counters(sensor.id)->memory_bytes.store(grid->MemoryBytes());
    }
  }
  const std::size_t changed_count = changed.size();
  PublishLocked(std::move(changed), /*reset=*/full_refresh);
  // Counted once published: a client that sees these numbers can query what they count.
  in_map_.store(integrated);
  renders_.fetch_add(1);
  spdlog::debug(
      "worker: rendered version {} ({} voxels changed) in {:.1f} ms ({:.1f} ms rendering and "
      "fusing the beam grids)",
      version_offset_ + rendered_map_version_, changed_count,
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count(),
      std::chrono::duration<double, std::milli>(rendered - start).count());
}

void FusionWorker::RebuildPublishedLocked() {
  published_ = base_ ? std::make_unique<octomap::OcTree>(*base_)
                     : std::make_unique<octomap::OcTree>(options_.map.resolution_m);
  published_->setOccupancyThres(options_.thresholds.occupied);
  const octomap::OcTree& live = map_->tree();
  for (auto it = live.begin_leafs(), end = live.end_leafs(); it != end; ++it) {
    // WorldMap keeps its leaves at full depth (it never prunes).
    if (it.getDepth() != live.getTreeDepth()) continue;
    if (const auto value = FusedLogOddsLocked(it.getKey())) {
      published_->setNodeValue(it.getKey(), *value);
    }
  }
}

void FusionWorker::PublishLocked(std::vector<octomap::OcTreeKey> changed, bool reset) {
  auto snapshot = std::make_shared<MapSnapshot>();
  snapshot->version = version_offset_ + map_->version();
  snapshot->tree = std::make_shared<const octomap::OcTree>(*published_);
  hub_->Publish(std::move(snapshot), std::move(changed), reset);
}

std::uint64_t FusionWorker::Reset() {
  std::lock_guard<std::mutex> lock(map_mutex_);
  version_offset_ = hub_->Current()->version + 1;
  base_.reset();
  RebuildMapLocked();
  for (const auto& sensor : sensors_) (void)map_->AddSensor(sensor.id, sensor.spec);
  PublishLocked({}, /*reset=*/true);
  spdlog::info("map reset; version {}", version_offset_);
  return version_offset_;
}

BeamLookup FusionWorker::InspectBeam(const std::string& sensor_id, std::optional<std::size_t> beam,
                                     std::size_t row, std::size_t col, BeamInspection* out) const {
  std::lock_guard<std::mutex> lock(map_mutex_);
  const BeamGrid* grid = map_->beam_grid(sensor_id);
  if (grid == nullptr) return BeamLookup::kUnknownSensor;
  const BeamTessellation& tess = grid->tessellation();
  if (!beam) {
    if (row >= static_cast<std::size_t>(tess.rows()) ||
        col >= static_cast<std::size_t>(tess.cols())) {
      return BeamLookup::kBeamOutOfRange;
    }
    beam = row * static_cast<std::size_t>(tess.cols()) + col;
  }
  if (*beam >= tess.beam_count()) return BeamLookup::kBeamOutOfRange;
  out->beam = *beam;
  out->cell_size_m = grid->options().cell_size_m;
  out->direction_sensor = tess.Direction(*beam);
  out->first_hit = grid->FirstHitProbabilities(*beam);
  out->cell_occupancy = grid->CellProbabilities(*beam);
  out->touched = grid->Touched(*beam);
  return BeamLookup::kOk;
}

}  // namespace fusion::service
