#include "fusion/service/fusion_worker.h"

#include <prometheus/histogram.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <deque>
#include <utility>

#include "fusion/core/projective_render.h"
#include "fusion/service/admission.h"

namespace fusion::service {

// A sensor's way through the worker. Lock order: map_mutex_, then Lane::mutex, then work_mutex_.
struct FusionWorker::Lane {
  const SensorSetup* setup = nullptr;
  SensorCountersAtomic* counters = nullptr;
  mutable std::mutex mutex;  // guards periods (the integrator, a render of the open period)
  // Null for a camera that waits for its CameraInfo (DefineSensor makes it).
  std::unique_ptr<SensorPeriods> periods;
  // Under mutex: the period whose grid the renderer reads without holding mutex (RenderOpen),
  // and the integrator's wait for it. A cloud that seals that period does not wait: it leaves
  // the grid as it is and starts a new period.
  const Period* rendering = nullptr;
  std::condition_variable rendered_cv;
  bool cloud_held = false;  // the integrator holds a cloud until that render ends (Integrate)
  // The spec its beam grid has, for SpecOf (which must not wait for a render of the period).
  mutable std::mutex spec_mutex;
  std::optional<SensorSpec> spec;
  // Arrival times of the integrated clouds not yet in a published map, oldest first (only
  // with the DDS-to-queryable histogram).
  std::deque<std::chrono::steady_clock::time_point> awaiting_publication;
  // Guarded by work_mutex_.
  std::size_t sealed_waiting = 0;  // sealed periods not yet committed
  bool dirty = false;              // the open period has frames its last render did not see
  // The open period's first frame came in and the map shows none of the period: rendered at
  // once (not after render_interval), so a moving sensor's frame is in the map without waiting
  // for the next frame to seal it; that render is then the one its commit uses.
  bool fresh = false;
  // The integrator's own: points outside the map are logged at most once a second.
  std::chrono::steady_clock::time_point last_outside_log{};
  std::uint64_t outside_not_logged = 0;
  // The renderer's own (under map_mutex_).
  std::uint64_t live_sequence = 0;  // the period the map's live contribution renders
  std::uint64_t live_frames = 0;    // and how many of its frames
  std::uint64_t committed_clouds = 0;
  std::uint64_t published_clouds = 0;  // committed + live as of the last publication
  std::chrono::steady_clock::time_point last_open_render{};
};

namespace {

using Clock = std::chrono::steady_clock;

double SecondsSince(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

void LowerPriority(int nice, const char* what) {
  // Queries come first: the worker's threads (and the render threads they start, which inherit
  // this) run at a lower priority than the gRPC and DDS threads (SetBackgroundPriority).
  if (nice > 0 && !SetBackgroundPriority(nice)) {
    spdlog::warn("worker: could not lower the priority of the {}: {}", what, std::strerror(errno));
  }
}

}  // namespace

FusionWorker::FusionWorker(WorkerOptions options, std::vector<SensorSetup> sensors,
                           IngestQueues* queues, SnapshotHub* hub)
    : options_(std::move(options)),
      render_options_(MapRenderOptions(options_.map)),
      sensors_(std::move(sensors)),
      queues_(queues),
      hub_(hub) {}

FusionWorker::~FusionWorker() { Stop(); }

Status FusionWorker::Start(std::unique_ptr<octomap::OcTree> history) {
  std::lock_guard<std::mutex> lock(map_mutex_);
  try {
    if (Status started = StartLocked(std::move(history)); !started.ok()) return started;
  } catch (const std::exception& e) {  // core refuses what validation let through
    return Status::Error(std::string("the map could not be set up: ") + e.what());
  }
  // spdlog's registry is a function-local static of an uninstrumented library: create it here,
  // before the threads that log, so its construction happens before their first use (what the
  // thread sanitizer can see; fusiond's main has logged long before, a test may not have).
  (void)spdlog::default_logger_raw();
  last_forget_ = std::chrono::steady_clock::now();
  integrator_ = std::thread([this] { IntegratorLoop(); });
  renderer_ = std::thread([this] { RendererLoop(); });
  return Status::Ok();
}

Status FusionWorker::StartLocked(std::unique_ptr<octomap::OcTree> history) {
  WorldMapOptions map_options = options_.map;
  map_options.occupancy_threshold = options_.thresholds.occupied;
  map_ = std::make_unique<WorldMap>(map_options);
  for (const auto& sensor : sensors_) {
    auto lane = std::make_unique<Lane>();
    lane->setup = &sensor;
    lane->counters = queues_->counters(sensor.id);
    // A camera whose intrinsics come from its CameraInfo gets its beam grid then (DefineSensor).
    if (!sensor.intrinsics_from_camera_info) {
      if (Status added = AddBeamGridLocked(*lane, sensor.spec); !added.ok()) return added;
    }
    lanes_.push_back(std::move(lane));
  }
  if (history) map_->LoadHistory(*history);
  PublishLocked();
  return Status::Ok();
}

Status FusionWorker::AddBeamGridLocked(Lane& lane, const SensorSpec& spec) {
  const std::string& id = lane.setup->id;
  const MapStatus status = map_->AddSensor(id, spec);
  if (status != MapStatus::kOk) {
    return Status::Error("sensor '" + id + "': " + MapStatusName(status));
  }
  auto periods = std::make_unique<SensorPeriods>(
      spec, SensorGridOptions(options_.map, spec), options_.map.pose_tolerance_m,
      options_.map.pose_tolerance_rad, options_.map.resolution_m);
  {
    std::lock_guard<std::mutex> lock(lane.spec_mutex);
    lane.spec = spec;
  }
  std::lock_guard<std::mutex> lock(lane.mutex);
  lane.periods = std::move(periods);
  return Status::Ok();
}

Status FusionWorker::DefineSensor(const std::string& sensor_id, const SensorSpec& spec) {
  std::lock_guard<std::mutex> lock(map_mutex_);
  Lane* lane = LaneOf(sensor_id);
  if (lane == nullptr || !lane->setup->intrinsics_from_camera_info) {
    return Status::Error("sensor '" + sensor_id + "' does not wait for its intrinsics");
  }
  if (map_->HasSensor(sensor_id)) return Status::Error("sensor '" + sensor_id + "' has its beams");
  try {
    return AddBeamGridLocked(*lane, spec);
  } catch (const std::exception& e) {  // core refuses what validation let through
    return Status::Error("sensor '" + sensor_id + "': " + e.what());
  }
}

std::optional<SensorSpec> FusionWorker::SpecOf(const std::string& sensor_id) const {
  const Lane* lane = LaneOf(sensor_id);
  if (lane == nullptr) return std::nullopt;
  std::lock_guard<std::mutex> lock(lane->spec_mutex);
  return lane->spec ? *lane->spec : lane->setup->spec;
}

void FusionWorker::Stop() {
  if (!integrator_.joinable()) return;
  {
    std::lock_guard<std::mutex> lock(work_mutex_);
    stop_ = true;
  }
  room_cv_.notify_all();
  queues_->Wake();
  integrator_.join();
  {
    std::lock_guard<std::mutex> lock(work_mutex_);
    integrator_done_ = true;
  }
  work_cv_.notify_all();
  renderer_.join();
}

FusionWorker::Lane* FusionWorker::LaneOf(const std::string& sensor_id) const {
  for (const auto& lane : lanes_) {
    if (lane->setup->id == sensor_id) return lane.get();
  }
  return nullptr;
}

// ---- integrator -------------------------------------------------------------------------------

void FusionWorker::IntegratorLoop() {
  LowerPriority(options_.nice, "integrator");
  std::vector<Cloud> clouds;
  std::deque<Cloud> held;  // popped, not yet integrated, in the order they came
  while (!stop_) {
    clouds.clear();
    // Woken (IngestQueues::Wake) also when a render ends that a held cloud waits for.
    queues_->PopAll(&clouds, std::chrono::steady_clock::now() + std::chrono::milliseconds(500));
    for (Cloud& cloud : clouds) held.push_back(std::move(cloud));
    IntegrateHeld(&held, /*wait=*/held.size() > kMaxHeldClouds);
  }
  do {  // what is still queued or held, each waiting for the renderer where it must
    clouds.clear();
    queues_->PopAll(&clouds, std::chrono::steady_clock::now());
    for (Cloud& cloud : clouds) held.push_back(std::move(cloud));
    IntegrateHeld(&held, /*wait=*/true);
  } while (!clouds.empty());
}

void FusionWorker::IntegrateHeld(std::deque<Cloud>* held, bool wait) {
  // A lane whose cloud must wait for a render keeps its later clouds behind that one: each
  // sensor's clouds are integrated in the order they came.
  std::vector<const Lane*> waiting;
  std::deque<Cloud> left;
  for (Cloud& cloud : *held) {
    const Lane* lane = LaneOf(cloud.sensor_id);
    const bool behind = std::find(waiting.begin(), waiting.end(), lane) != waiting.end();
    if (behind || !Integrate(cloud, wait)) {
      if (!behind) waiting.push_back(lane);
      left.push_back(std::move(cloud));
    }
  }
  held->swap(left);
}

bool FusionWorker::Integrate(const Cloud& cloud, bool wait) {
  Lane* lane = LaneOf(cloud.sensor_id);
  if (lane == nullptr || lane->counters == nullptr) return true;
  const Eigen::Isometry3d T_world_sensor =
      cloud.T_world_published * lane->setup->T_published_sensor;
  bool may_seal = true;
  {
    std::unique_lock<std::mutex> lock(work_mutex_);
    if (options_.wait_for_renderer) {
      // Also while stopping: the renderer runs until the integrator is done, and what is still
      // queued is mapped as taken, not merged.
      room_cv_.wait(lock, [&] { return lane->sealed_waiting < kMaxSealedPeriods; });
    }
    may_seal = lane->sealed_waiting < kMaxSealedPeriods;
  }
  PeriodIntegration result;
  std::unique_ptr<Period> sealed;
  MapStatus status = MapStatus::kInvalidArgument;
  bool opened = false;
  {
    std::unique_lock<std::mutex> lock(lane->mutex);
    if (!lane->periods) {  // only a fusion/points cloud can come before the CameraInfo
      queues_->CountRejected(cloud.sensor_id, RejectReason::kNoCameraInfo);
      rejections_.Log(RejectReason::kNoCameraInfo, cloud.sensor_id,
                      "the sensor has no beams before its first CameraInfo");
      return true;
    }
    // Into a period the renderer is reading only after that render; sealing it leaves it alone.
    // Without `wait`, the cloud is held meanwhile and the renderer wakes the integrator after.
    const auto free_to_integrate = [&] {
      return lane->rendering != &lane->periods->open() ||
             (may_seal && lane->periods->WouldSeal(T_world_sensor));
    };
    if (!wait && !free_to_integrate()) {
      lane->cloud_held = true;
      return false;
    }
    lane->rendered_cv.wait(lock, free_to_integrate);
    const auto start = options_.histograms.integration_seconds ? Clock::now() : Clock::time_point{};
    try {
      status = lane->periods->Integrate(T_world_sensor, cloud.xyz.data(), cloud.xyz.size() / 3,
                                        cloud.beyond_range, may_seal, &result, &sealed);
    } catch (const std::exception& e) {
      spdlog::error("worker: cloud {} of '{}' failed: {}", cloud.sequence_number,
                    cloud.sensor_id, e.what());
      return true;
    }
    ObserveIntegration(*lane, cloud, start, status);
    lane->counters->memory_bytes.store(lane->periods->MemoryBytes());
    opened = status == MapStatus::kOk && lane->periods->open().frames == 1;
  }
  if (status != MapStatus::kOk) {
    spdlog::warn("worker: cloud {} of '{}' not integrated: {}", cloud.sequence_number,
                 cloud.sensor_id, MapStatusName(status));
    return true;
  }
  {
    std::lock_guard<std::mutex> lock(work_mutex_);
    if (sealed) {
      sealed_.push_back({lane, std::move(sealed)});
      ++lane->sealed_waiting;
    }
    lane->dirty = true;
    lane->fresh = lane->fresh || opened;
  }
  work_cv_.notify_one();
  integrated_.fetch_add(1, std::memory_order_relaxed);
  SensorCountersAtomic& c = *lane->counters;
  c.integrated.fetch_add(1, std::memory_order_relaxed);
  if (result.merged) c.merged.fetch_add(1, std::memory_order_relaxed);
  c.changes_detected.fetch_add(result.stats.changes_detected, std::memory_order_relaxed);
  c.points_updated.fetch_add(result.stats.updated, std::memory_order_relaxed);
  c.points_beyond_range.fetch_add(result.stats.beyond_range, std::memory_order_relaxed);
  c.points_missing.fetch_add(result.stats.missing, std::memory_order_relaxed);
  c.points_rejected.fetch_add(result.stats.rejected_nonfinite + result.stats.rejected_outside_fov +
                                  result.stats.rejected_outside_map,
                              std::memory_order_relaxed);
  if (result.stats.rejected_outside_map > 0) {
    const auto now = std::chrono::steady_clock::now();
    if (now - lane->last_outside_log < std::chrono::seconds(1)) {
      lane->outside_not_logged += result.stats.rejected_outside_map;
    } else {
      spdlog::warn("worker: cloud {} of '{}': {} points outside the map (beyond +-{:.0f} m at "
                   "{} m voxels) left out{}",
                   cloud.sequence_number, cloud.sensor_id, result.stats.rejected_outside_map,
                   MapHalfExtentM(options_.map.resolution_m), options_.map.resolution_m,
                   lane->outside_not_logged > 0
                       ? fmt::format(" [{} more since the last line]", lane->outside_not_logged)
                       : "");
      lane->last_outside_log = now;
      lane->outside_not_logged = 0;
    }
  }
  spdlog::debug("worker: cloud {} of '{}': {} updated, {} beyond range, {} missing{}",
                cloud.sequence_number, cloud.sensor_id, result.stats.updated,
                result.stats.beyond_range, result.stats.missing,
                result.merged ? " (merged: the renderer is behind)" : "");
  return true;
}

// Under lane.mutex; `start` is when the integration began (read only with that histogram).
void FusionWorker::ObserveIntegration(Lane& lane, const Cloud& cloud, Clock::time_point start,
                                      MapStatus status) {
  const WorkerHistograms& histograms = options_.histograms;
  if (histograms.integration_seconds) histograms.integration_seconds->Observe(SecondsSince(start));
  if (histograms.dds_to_queryable_seconds && status == MapStatus::kOk) {
    lane.awaiting_publication.push_back(cloud.received_at);
  }
}

// ---- renderer ---------------------------------------------------------------------------------

void FusionWorker::RendererLoop() {
  LowerPriority(options_.nice, "renderer");
  using Clock = std::chrono::steady_clock;
  while (true) {
    bool did = false;
    {
      std::lock_guard<std::mutex> lock(map_mutex_);
      did = RenderStep();
    }
    if (did) continue;
    std::unique_lock<std::mutex> lock(work_mutex_);
    // Nothing to do now: wait for a sealed period, new frames, the next render slot, or the end.
    auto next = Clock::now() + std::chrono::seconds(1);
    bool any_dirty = false;
    for (const auto& lane : lanes_) {
      if (!lane->dirty) continue;
      any_dirty = true;
      next = std::min(next, lane->last_open_render + options_.render_interval);
    }
    if (integrator_done_ && sealed_.empty() && !any_dirty) break;
    if (!sealed_.empty()) continue;
    work_cv_.wait_until(lock, next, [&] {
      if (!sealed_.empty() || integrator_done_) return true;
      for (const auto& lane : lanes_) {
        if (lane->dirty && lane->sealed_waiting == 0 && OpenRenderDue(*lane, Clock::now())) {
          return true;
        }
      }
      return false;
    });
  }
}

bool FusionWorker::RenderStep() {
  Sealed sealed{nullptr, nullptr};
  {
    std::lock_guard<std::mutex> lock(work_mutex_);
    if (!sealed_.empty()) {
      sealed = std::move(sealed_.front());
      sealed_.pop_front();
    }
  }
  if (sealed.lane != nullptr) {
    CommitSealed(std::move(sealed));
    PublishLocked();
    return true;
  }
  const auto now = std::chrono::steady_clock::now();
  if (ForgetStep(now)) return true;
  for (const auto& lane : lanes_) {
    {
      std::lock_guard<std::mutex> lock(work_mutex_);
      const bool due = integrator_done_ || OpenRenderDue(*lane, now);
      if (!lane->dirty || lane->sealed_waiting > 0 || !due) continue;
      lane->dirty = false;
      lane->fresh = false;
    }
    if (RenderOpen(*lane)) {
      PublishLocked();
      return true;
    }
  }
  return false;
}

bool FusionWorker::OpenRenderDue(const Lane& lane, Clock::time_point now) const {
  return lane.fresh || now >= lane.last_open_render + options_.render_interval;
}

bool FusionWorker::ForgetStep(std::chrono::steady_clock::time_point now) {
  const double half_life_s = options_.map.forget_half_life_s;
  if (!(half_life_s > 0.0)) return false;
  // A twentieth of the half-life (each step re-fuses the whole map), at most once a second
  // (the renderer wakes that often) and at least once a minute.
  const auto interval = std::chrono::duration_cast<std::chrono::steady_clock::duration>(
      std::chrono::duration<double>(std::clamp(half_life_s / 20.0, 1.0, 60.0)));
  if (now < last_forget_ + interval) return false;
  const double elapsed_s = std::chrono::duration<double>(now - last_forget_).count();
  last_forget_ = now;
  const std::uint64_t forgotten = map_->Forget(elapsed_s);
  PublishLocked();
  spdlog::debug("forgetting: {:.2f} s passed over the history, {} nodes forgotten; version {}",
                elapsed_s, forgotten, published_version_);
  return true;
}

void FusionWorker::CommitSealed(Sealed sealed) {
  Lane& lane = *sealed.lane;
  const Period& period = *sealed.period;
  const std::string& id = lane.setup->id;
  try {
    // The map may hold this period's render already (made while it was open).
    const Clock::time_point start = Clock::now();
    const bool render = lane.live_sequence != period.sequence || lane.live_frames != period.frames;
    if (render) {
      const SaturatedFree skip = map_->Saturation(id);
      const Clock::time_point render_start = Clock::now();
      (void)map_->ReplaceLive(
          id, Render(*period.grid, period.T_world_sensor, render_options_, nullptr, &skip,
                     &map_->render_scratch()));
      if (auto* h = options_.histograms.render_seconds) h->Observe(SecondsSince(render_start));
      renders_.fetch_add(1);
    }
    (void)map_->CommitLive(id);
    spdlog::debug("worker: period {} of '{}' ({} frames) committed in {:.1f} ms{}", period.sequence,
                  id, period.frames, 1e3 * SecondsSince(start), render ? ", rendered first" : "");
  } catch (const std::exception& e) {
    spdlog::error("worker: period {} of '{}' not committed: {}", period.sequence, id, e.what());
  }
  lane.committed_clouds += period.frames;
  lane.live_sequence = 0;
  lane.live_frames = 0;
  {
    std::lock_guard<std::mutex> lock(lane.mutex);
    lane.periods->Recycle(std::move(sealed.period));
  }
  {
    std::lock_guard<std::mutex> lock(work_mutex_);
    --lane.sealed_waiting;
  }
  room_cv_.notify_all();
}

bool FusionWorker::RenderOpen(Lane& lane) {
  RenderedGrid grid(options_.map.resolution_m);
  std::uint64_t sequence = 0, frames = 0;
  const Period* open = nullptr;
  const auto start = std::chrono::steady_clock::now();
  {
    std::lock_guard<std::mutex> lock(lane.mutex);
    {
      std::lock_guard<std::mutex> work(work_mutex_);
      if (lane.sealed_waiting > 0) return false;  // sealed meanwhile: commit that first
    }
    open = &lane.periods->open();
    if (open->frames == 0 ||
        (open->sequence == lane.live_sequence && open->frames == lane.live_frames)) {
      return false;
    }
    sequence = open->sequence;
    frames = open->frames;
    // The integrator leaves this grid alone until the render is done, unless it seals the
    // period (then the period waits, unchanged, among the sealed ones: this render serves its
    // commit). Sealed periods are consumed only here, on the renderer's thread.
    lane.rendering = open;
  }
  bool rendered = true;
  try {
    const SaturatedFree skip = map_->Saturation(lane.setup->id);
    const Clock::time_point render_start = Clock::now();
    grid = Render(*open->grid, open->T_world_sensor, render_options_, nullptr, &skip,
                  &map_->render_scratch());
    if (auto* h = options_.histograms.render_seconds) h->Observe(SecondsSince(render_start));
  } catch (const std::exception& e) {
    spdlog::error("worker: render of '{}' failed: {}", lane.setup->id, e.what());
    rendered = false;
  }
  bool held = false;
  {
    std::lock_guard<std::mutex> lock(lane.mutex);
    lane.rendering = nullptr;
    held = std::exchange(lane.cloud_held, false);
  }
  lane.rendered_cv.notify_all();
  if (held) queues_->Wake();
  if (!rendered) return false;
  const Clock::time_point replace_start = Clock::now();
  (void)map_->ReplaceLive(lane.setup->id, std::move(grid));
  spdlog::debug("worker: period {} of '{}' ({} frames) rendered in {:.1f} ms, into the map in "
                "{:.1f} ms",
                sequence, lane.setup->id, frames,
                1e3 * std::chrono::duration<double>(replace_start - start).count(),
                1e3 * SecondsSince(replace_start));
  lane.live_sequence = sequence;
  lane.live_frames = frames;
  lane.last_open_render = start;
  renders_.fetch_add(1);
  return true;
}

void FusionWorker::PublishLocked() {
  Publication publication = map_->Publish();
  std::uint64_t in_map = 0;
  for (const auto& lane : lanes_) in_map += lane->committed_clouds + lane->live_frames;
  if (publication.changes.version != published_version_) {
    auto snapshot = std::make_shared<MapSnapshot>();
    snapshot->version = publication.changes.version;
    snapshot->tree = publication.tree;
    snapshot->leaves = publication.leaves;
    published_version_ = snapshot->version;
    spdlog::debug("worker: published version {} ({} regions changed)", published_version_,
                  publication.changes.regions.size());
    hub_->Publish(std::move(snapshot), std::move(publication.changes));
  }
  // Counted once published: a client that sees these numbers can query what they count, and
  // finds every cloud they count in the DDS-to-queryable histogram already (observed first).
  if (options_.histograms.dds_to_queryable_seconds) ObserveQueryable();
  in_map_.store(in_map);
}

// A lane's clouds reach the map in the order they were integrated (sealed periods before the
// open one), so the ones that became queryable are the oldest awaiting.
void FusionWorker::ObserveQueryable() {
  const Clock::time_point now = Clock::now();
  for (const auto& lane : lanes_) {
    const std::uint64_t in_map = lane->committed_clouds + lane->live_frames;
    if (in_map > lane->published_clouds) {
      std::lock_guard<std::mutex> lock(lane->mutex);
      auto& awaiting = lane->awaiting_publication;
      for (std::uint64_t n = in_map - lane->published_clouds; n > 0 && !awaiting.empty(); --n) {
        options_.histograms.dds_to_queryable_seconds->Observe(
            std::chrono::duration<double>(now - awaiting.front()).count());
        awaiting.pop_front();
      }
    }
    lane->published_clouds = in_map;
  }
}

std::uint64_t FusionWorker::Reset() {
  std::lock_guard<std::mutex> lock(map_mutex_);
  for (const auto& lane : lanes_) {
    std::lock_guard<std::mutex> lane_lock(lane->mutex);
    if (lane->periods) lane->periods->Reset();
    lane->live_sequence = lane->live_frames = lane->committed_clouds = 0;
    lane->published_clouds = 0;
    lane->awaiting_publication.clear();
  }
  {
    std::lock_guard<std::mutex> work(work_mutex_);
    sealed_.clear();
    for (const auto& lane : lanes_) {
      lane->sealed_waiting = 0;
      lane->dirty = false;
    }
  }
  room_cv_.notify_all();
  map_->Reset();
  PublishLocked();
  spdlog::info("map reset; version {}", published_version_);
  return published_version_;
}

std::uint64_t FusionWorker::ClearBox(const Eigen::AlignedBox3d& box_world,
                                     std::uint64_t* voxels) {
  std::lock_guard<std::mutex> lock(map_mutex_);
  for (const auto& lane : lanes_) {
    std::unique_ptr<Period> open;
    {
      std::lock_guard<std::mutex> lane_lock(lane->mutex);
      if (lane->periods) open = lane->periods->Seal();
    }
    if (!open) continue;
    std::lock_guard<std::mutex> work(work_mutex_);
    sealed_.push_back({lane.get(), std::move(open)});
    ++lane->sealed_waiting;
  }
  for (;;) {
    Sealed sealed{nullptr, nullptr};
    {
      std::lock_guard<std::mutex> work(work_mutex_);
      if (sealed_.empty()) break;
      sealed = std::move(sealed_.front());
      sealed_.pop_front();
    }
    CommitSealed(std::move(sealed));
  }
  *voxels = map_->ClearBox(box_world);
  PublishLocked();
  spdlog::info("box [{:.3f} {:.3f} {:.3f}] - [{:.3f} {:.3f} {:.3f}] cleared: {} voxels; version {}",
               box_world.min().x(), box_world.min().y(), box_world.min().z(), box_world.max().x(),
               box_world.max().y(), box_world.max().z(), *voxels, published_version_);
  return published_version_;
}

BeamLookup FusionWorker::InspectBeam(const std::string& sensor_id, std::optional<std::size_t> beam,
                                     std::size_t row, std::size_t col, BeamInspection* out) const {
  const Lane* lane = LaneOf(sensor_id);
  if (lane == nullptr) return BeamLookup::kUnknownSensor;
  std::lock_guard<std::mutex> lock(lane->mutex);
  if (!lane->periods) return BeamLookup::kBeamOutOfRange;  // no beams before its CameraInfo
  // Beams are numbered as the sensor's; the period's grid reaches beyond them by a margin.
  const SensorSpec& spec = lane->periods->spec();
  const auto cols = static_cast<std::size_t>(spec.cols);
  const auto rows = static_cast<std::size_t>(spec.rows);
  if (beam) {
    if (*beam >= cols * rows) return BeamLookup::kBeamOutOfRange;
    row = *beam / cols;
    col = *beam % cols;
  } else if (row >= rows || col >= cols) {
    return BeamLookup::kBeamOutOfRange;
  }
  const BeamGrid& grid = *lane->periods->open().grid;
  const BeamTessellation& tess = grid.tessellation();
  const BeamMargin& margin = lane->periods->beam_margin();
  const std::size_t in_grid = (row + static_cast<std::size_t>(margin.rows)) *
                                  static_cast<std::size_t>(tess.cols()) +
                              col + static_cast<std::size_t>(margin.cols);
  out->beam = row * cols + col;
  out->cell_size_m = grid.options().cell_size_m;
  out->direction_sensor = tess.Direction(in_grid);
  out->first_hit = grid.FirstHitProbabilities(in_grid);
  out->cell_occupancy = grid.CellProbabilities(in_grid);
  out->touched = grid.Touched(in_grid);
  return BeamLookup::kOk;
}

}  // namespace fusion::service
