// Speed of rendering beam grids into the map (issues 4 and 10): the projective render against
// its oracle (the ray-traced render), render + fuse, and the stationary and moving workflows
// against OctoMap's insertPointCloud on the same simulated clouds, as ratios measured in the
// same run.
//
//   bench_map --benchmark_min_time=0.2
//   bench_map --benchmark_filter=Versus      # only the side-by-side runs against OctoMap
#include <benchmark/benchmark.h>

#include <chrono>
#include <cmath>
#include <vector>

#include "fusion/core/local_grid.h"
#include "fusion/core/planes.h"
#include "fusion/core/projective_render.h"
#include "fusion/core/world_map.h"
#include "fusion/sim/experiment.h"
#include "fusion/sim/scene.h"
#include "fusion/sim/simulator.h"

namespace {

constexpr double kResolutionM = 0.02;
constexpr int kStationaryFrames = 30;
// The moving drive: 30 Hz, 0.17 m/s sideways and 4 deg/s of yaw (issue 10's waypoints).
constexpr double kFrameRateHz = 30.0;
constexpr double kSpeedMps = 0.17;
constexpr double kYawRateDegps = 4.0;
constexpr int kMovingFrames = 12;

using Clock = std::chrono::steady_clock;

double MillisecondsSince(Clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

struct Fixture {
  fusion::sim::Scene scene = fusion::sim::PaperBoardScene();
  fusion::sim::SensorRun sr = fusion::sim::PaperSensorRuns()[0];
  std::vector<fusion::sim::OrganizedCloud> frames;
  Fixture() {
    sr.frames = kStationaryFrames;
    frames = fusion::sim::SimulateRun(scene, sr);
  }
};

const Fixture& SharedFixture() {
  static const Fixture fixture;
  return fixture;
}

// A sensor of `run` driving from its pose: frame k at k / 30 s.
struct Drive {
  std::vector<Eigen::Isometry3d> poses;
  std::vector<fusion::sim::OrganizedCloud> clouds;
};

Drive MakeDrive(const fusion::sim::SensorRun& run, int frames) {
  fusion::sim::RangeSimulator simulator(fusion::sim::PaperBoardScene(), run.spec, run.sim);
  Drive d;
  for (int k = 0; k < frames; ++k) {
    const double t_s = k / kFrameRateHz;
    Eigen::Isometry3d T = run.T_world_sensor;
    T.translation().y() += kSpeedMps * t_s;
    T.linear() = Eigen::AngleAxisd(kYawRateDegps * t_s * M_PI / 180.0, Eigen::Vector3d::UnitZ())
                     .toRotationMatrix() *
                 T.linear();
    d.poses.push_back(T);
    d.clouds.push_back(simulator.Capture(T));
  }
  return d;
}

const Drive& SrDrive() {
  static const Drive drive = MakeDrive(SharedFixture().sr, kMovingFrames);
  return drive;
}

fusion::WorldMapOptions MapOptions(double max_range_m = 1e9) {
  fusion::WorldMapOptions options;
  options.resolution_m = kResolutionM;
  options.render.max_range_m = max_range_m;
  return options;
}

fusion::BeamGridOptions GridOptions() { return fusion::SensorGridOptions(MapOptions()); }

// Change detection off (change_run 0): the integrator alone.
void BM_IntegrateSr3000Frame(benchmark::State& state) {
  const Fixture& f = SharedFixture();
  fusion::BeamGridOptions options = GridOptions();
  options.change_run = 0;
  fusion::BeamGrid grid(f.sr.spec, options);
  std::size_t i = 0;
  for (auto _ : state) {
    const auto& cloud = f.frames[i++ % f.frames.size()];
    benchmark::DoNotOptimize(grid.Integrate(cloud.xyz.data(), cloud.size(), cloud.beyond_range));
  }
}
BENCHMARK(BM_IntegrateSr3000Frame)->Unit(benchmark::kMillisecond);

// A moving sensor's frame: the grid reset (a recycled period's) and one frame integrated into
// beams at their prior, which first split their lists around every reading's ROI.
void BM_IntegrateSr3000FrameFreshPeriod(benchmark::State& state) {
  const Fixture& f = SharedFixture();
  fusion::BeamGrid grid(f.sr.spec, GridOptions());
  std::size_t i = 0;
  for (auto _ : state) {
    const auto& cloud = f.frames[i++ % f.frames.size()];
    grid.Reset();
    benchmark::DoNotOptimize(grid.Integrate(cloud.xyz.data(), cloud.size(), cloud.beyond_range));
  }
  state.counters["cells_per_beam"] = static_cast<double>(grid.cells_per_beam());
}
BENCHMARK(BM_IntegrateSr3000FrameFreshPeriod)->Unit(benchmark::kMillisecond);

// The same with change detection on (BeamGridOptions::change_run = 3, the default): the ROI
// masses the updates return, judged beam by beam once per cloud (docs/mapping.md, "A world
// that changes").
void BM_IntegrateSr3000FrameChangeDetection(benchmark::State& state) {
  const Fixture& f = SharedFixture();
  fusion::BeamGridOptions options = GridOptions();
  options.change_run = 3;
  fusion::BeamGrid grid(f.sr.spec, options);
  std::size_t i = 0, changes = 0;
  for (auto _ : state) {
    const auto& cloud = f.frames[i++ % f.frames.size()];
    changes += grid.Integrate(cloud.xyz.data(), cloud.size(), cloud.beyond_range).changes_detected;
  }
  state.counters["changes"] = static_cast<double>(changes);  // a static scene: expect 0
}
BENCHMARK(BM_IntegrateSr3000FrameChangeDetection)->Unit(benchmark::kMillisecond);

// Renders (fusion::Render) a beam grid of `clouds` seen from T, timed, with the render's counts.
void RenderFrames(benchmark::State& state, const fusion::SensorSpec& spec,
                  const std::vector<fusion::sim::OrganizedCloud>& clouds,
                  const Eigen::Isometry3d& T, const fusion::RenderOptions& options) {
  fusion::BeamGrid grid(spec, GridOptions());
  for (const auto& cloud : clouds) grid.Integrate(cloud.xyz.data(), cloud.size(), cloud.beyond_range);
  fusion::RenderStats stats;
  fusion::RenderScratch scratch;  // as the map keeps one: each render reuses the last's buffers
  for (auto _ : state) {
    stats = {};
    fusion::RenderedGrid rendered = fusion::Render(grid, T, options, &stats, nullptr, &scratch);
    benchmark::DoNotOptimize(rendered.size());
    scratch.Recycle(std::move(rendered));
  }
  state.counters["coarse_nodes"] = static_cast<double>(stats.coarse_nodes);
  state.counters["fine_voxels"] = static_cast<double>(stats.fine_voxels);
  state.counters["traced_voxels"] = static_cast<double>(stats.voxels);
  state.counters["segments"] = static_cast<double>(stats.segments);
}

fusion::RenderOptions Options(double resolution_m, fusion::RenderMethod method) {
  fusion::RenderOptions options;
  options.resolution_m = resolution_m;
  options.method = method;
  return options;
}

// A 30-frame SR-3000 grid at 2 cm: the projective render (arg 0) and its oracle (arg 1).
void BM_RenderSr3000(benchmark::State& state) {
  const Fixture& f = SharedFixture();
  const auto method =
      state.range(0) == 0 ? fusion::RenderMethod::kProjective : fusion::RenderMethod::kRayTraced;
  state.SetLabel(state.range(0) == 0 ? "projective" : "ray-traced (oracle)");
  RenderFrames(state, f.sr.spec, f.frames, f.sr.T_world_sensor, Options(kResolutionM, method));
}
BENCHMARK(BM_RenderSr3000)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond);

// One SR-3000 frame at 5 cm, rays to the sensor's full range (target <= 10 ms).
// Arg: render threads (RenderOptions::threads).
void BM_RenderSr3000OneFrame5cm(benchmark::State& state) {
  const Fixture& f = SharedFixture();
  fusion::RenderOptions options = Options(0.05, fusion::RenderMethod::kProjective);
  options.threads = static_cast<unsigned>(state.range(0));
  RenderFrames(state, f.sr.spec, {f.frames[0]}, f.sr.T_world_sensor, options);
}
BENCHMARK(BM_RenderSr3000OneFrame5cm)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond);

// One stereo frame at its full 640 x 480 pixels as beams, 2 cm (target <= 33 ms). Arg: render
// threads.
void BM_RenderStocFullResolution(benchmark::State& state) {
  fusion::sim::PaperRunOptions run_options;
  run_options.stereo_cols = 640;
  run_options.stereo_rows = 480;
  const fusion::sim::SensorRun stoc = fusion::sim::PaperSensorRuns(run_options)[1];
  fusion::sim::RangeSimulator simulator(fusion::sim::PaperBoardScene(), stoc.spec, stoc.sim);
  fusion::RenderOptions options = Options(kResolutionM, fusion::RenderMethod::kProjective);
  options.threads = static_cast<unsigned>(state.range(0));
  RenderFrames(state, stoc.spec, {simulator.Capture(stoc.T_world_sensor)}, stoc.T_world_sensor,
               options);
}
BENCHMARK(BM_RenderStocFullResolution)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond);

// Re-render of the same 30-frame period into the 2 cm world map (replaces the live part).
void BM_RenderAndFuseSr3000(benchmark::State& state) {
  const Fixture& f = SharedFixture();
  fusion::WorldMap map(MapOptions());
  (void)map.AddSensor("sr", f.sr.spec);
  for (const auto& cloud : f.frames) {
    (void)map.Integrate("sr", f.sr.T_world_sensor, cloud.xyz.data(), cloud.size(),
                        cloud.beyond_range);
  }
  for (auto _ : state) benchmark::DoNotOptimize(map.Render("sr"));
  state.counters["map_leaves"] = static_cast<double>(map.tree().getNumLeafNodes());
}
BENCHMARK(BM_RenderAndFuseSr3000)->Unit(benchmark::kMillisecond);

// Stationary workflow, ours and OctoMap's in the same run: 30 SR-3000 frames integrated and one
// render + fuse, against the same 30 frames inserted into OctoMap at 2 cm.
void BM_StationaryVersusOctoMap(benchmark::State& state) {
  const Fixture& f = SharedFixture();
  double ours_ms = 0.0, octomap_ms = 0.0;
  for (auto _ : state) {
    auto t0 = Clock::now();
    fusion::WorldMap map(MapOptions());
    (void)map.AddSensor("sr", f.sr.spec);
    for (const auto& cloud : f.frames) {
      (void)map.Integrate("sr", f.sr.T_world_sensor, cloud.xyz.data(), cloud.size(),
                          cloud.beyond_range);
    }
    (void)map.Render("sr");
    ours_ms = MillisecondsSince(t0);
    t0 = Clock::now();
    octomap::OcTree tree(kResolutionM);
    for (const auto& cloud : f.frames) {
      fusion::sim::InsertIntoOctoMap(cloud, f.sr.T_world_sensor, f.sr.spec.r_max_m, &tree);
    }
    octomap_ms = MillisecondsSince(t0);
  }
  state.counters["ours_ms"] = ours_ms;
  state.counters["octomap_ms"] = octomap_ms;
  state.counters["speedup"] = octomap_ms / ours_ms;
}
BENCHMARK(BM_StationaryVersusOctoMap)->Unit(benchmark::kMillisecond)->Iterations(1);

// Moving, per frame, ours and OctoMap's in the same run: the SR-3000 drives (a new pose every
// frame), each frame integrated, rendered and fused (committing the frame before), against one
// insertPointCloud per frame of the same drive (run after ours); rays to the sensor's range
// (first arg 0) or to 4 m (1, the deployment's map.max_range_m), for both; second arg: our render
// threads (OctoMap inserts on one). Also the memory of the two maps after the drive.
void BM_MovingVersusOctoMap(benchmark::State& state) {
  const Fixture& f = SharedFixture();
  const Drive& drive = SrDrive();
  const double max_range_m = state.range(0) == 0 ? f.sr.spec.r_max_m : 4.0;
  state.SetLabel(state.range(0) == 0 ? "full range" : "rays to 4 m");
  double ours_ms = 0.0, integrate_ms = 0.0, octomap_ms = 0.0;
  std::size_t ours_bytes = 0, octomap_bytes = 0;
  fusion::RenderStats render;  // summed over the frames after the first
  for (auto _ : state) {
    fusion::WorldMapOptions options = MapOptions(max_range_m);
    options.render.threads = static_cast<unsigned>(state.range(1));
    fusion::WorldMap map(options);
    (void)map.AddSensor("sr", f.sr.spec);
    octomap::OcTree tree(kResolutionM);
    ours_ms = integrate_ms = octomap_ms = 0.0;
    render = {};
    for (std::size_t k = 0; k < drive.poses.size(); ++k) {
      const auto& cloud = drive.clouds[k];
      auto t0 = Clock::now();
      (void)map.Integrate("sr", drive.poses[k], cloud.xyz.data(), cloud.size(), cloud.beyond_range);
      const double integrated_ms = MillisecondsSince(t0);
      fusion::FuseStats fuse;
      (void)map.Render("sr", &fuse);
      if (k > 0) {  // the first frame builds the beam grids
        ours_ms += MillisecondsSince(t0);
        integrate_ms += integrated_ms;
        render.coarse_nodes += fuse.render.coarse_nodes;
        render.fine_voxels += fuse.render.fine_voxels;
        render.segments += fuse.render.segments;
      }
    }
    // OctoMap's drive after ours, not frame by frame between: each insertPointCloud frees ~1 M
    // small hash-set nodes, and the next large allocation of whoever runs next pays for sorting
    // them out of malloc's bins (measured: ~7 us per beam-pool allocation of ours when
    // interleaved), which neither system pays in a process of its own.
    for (std::size_t k = 0; k < drive.poses.size(); ++k) {
      const auto t0 = Clock::now();
      fusion::sim::InsertIntoOctoMap(drive.clouds[k], drive.poses[k], max_range_m, &tree);
      if (k > 0) octomap_ms += MillisecondsSince(t0);
    }
    ours_bytes = map.tree().memoryUsage();
    octomap_bytes = tree.memoryUsage();
  }
  const double frames = static_cast<double>(drive.poses.size() - 1);
  state.counters["ours_ms_per_frame"] = ours_ms / frames;
  state.counters["octomap_ms_per_frame"] = octomap_ms / frames;
  state.counters["speedup"] = octomap_ms / ours_ms;
  // Where our time goes: integration, and the render with the fuse into the map.
  state.counters["ours_integrate_ms"] = integrate_ms / frames;
  state.counters["ours_render_fuse_ms"] = (ours_ms - integrate_ms) / frames;
  state.counters["coarse_nodes"] = static_cast<double>(render.coarse_nodes) / frames;
  state.counters["fine_voxels"] = static_cast<double>(render.fine_voxels) / frames;
  state.counters["segments"] = static_cast<double>(render.segments) / frames;
  state.counters["ours_map_MB"] = static_cast<double>(ours_bytes) / 1e6;
  state.counters["octomap_MB"] = static_cast<double>(octomap_bytes) / 1e6;
}
BENCHMARK(BM_MovingVersusOctoMap)
    ->Args({0, 1})
    ->Args({1, 1})
    ->Args({0, 2})
    ->Unit(benchmark::kMillisecond)
    ->Iterations(1);

// Hough planes on the stationary map.
void BM_HoughPlanes(benchmark::State& state) {
  const Fixture& f = SharedFixture();
  fusion::WorldMap map(MapOptions());
  (void)map.AddSensor("sr", f.sr.spec);
  for (const auto& cloud : f.frames) {
    (void)map.Integrate("sr", f.sr.T_world_sensor, cloud.xyz.data(), cloud.size(),
                        cloud.beyond_range);
  }
  (void)map.Render("sr");
  for (auto _ : state) benchmark::DoNotOptimize(fusion::DetectPlanes(map.tree()));
}
BENCHMARK(BM_HoughPlanes)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
