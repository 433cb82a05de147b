// Speed of issue 4: rendering beam grids into local grids, fusing them into the
// world map, and the stationary / moving workflows against OctoMap on the same
// simulated clouds.
//
//   bench_map --benchmark_min_time=0.2
#include <benchmark/benchmark.h>

#include <vector>

#include "fusion/core/local_grid.h"
#include "fusion/core/planes.h"
#include "fusion/core/world_map.h"
#include "fusion/sim/experiment.h"
#include "fusion/sim/scene.h"

namespace {

constexpr double kResolutionM = 0.02;
constexpr int kStationaryFrames = 30;

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

fusion::WorldMapOptions MapOptions() {
  fusion::WorldMapOptions options;
  options.resolution_m = kResolutionM;
  return options;
}

fusion::BeamGridOptions GridOptions() {
  // The beam grid WorldMap would give the sensor (its prior included).
  fusion::BeamGridOptions options = MapOptions().beam_grid;
  options.prior_reference_length_m = MapOptions().beam_prior_length_m;
  return options;
}

void BM_IntegrateSr3000Frame(benchmark::State& state) {
  const Fixture& f = SharedFixture();
  fusion::BeamGrid grid(f.sr.spec, GridOptions());
  std::size_t i = 0;
  for (auto _ : state) {
    const auto& cloud = f.frames[i++ % f.frames.size()];
    benchmark::DoNotOptimize(grid.Integrate(cloud.xyz.data(), cloud.size(), cloud.beyond_range));
  }
}
BENCHMARK(BM_IntegrateSr3000Frame)->Unit(benchmark::kMillisecond);

// Renders a beam grid of the first `frames` SR-3000 frames with `options`, timed, and reports
// the render's counts.
void RenderSr3000Frames(benchmark::State& state, std::size_t frames,
                        const fusion::RenderOptions& options) {
  const Fixture& f = SharedFixture();
  fusion::BeamGrid grid(f.sr.spec, GridOptions());
  for (std::size_t i = 0; i < frames; ++i) {
    const auto& cloud = f.frames[i % f.frames.size()];
    grid.Integrate(cloud.xyz.data(), cloud.size(), cloud.beyond_range);
  }
  fusion::RenderStats stats;
  for (auto _ : state) {
    auto local = fusion::RenderBeamGrid(grid, f.sr.T_world_sensor, options, &stats);
    benchmark::DoNotOptimize(local.size());
  }
  state.counters["voxels"] = static_cast<double>(stats.voxels);
  state.counters["segments"] = static_cast<double>(stats.segments);
  state.counters["rays"] = static_cast<double>(stats.rays_traced);
}

// Rendering a 30-frame SR-3000 beam grid into a 2 cm local grid, on 1 or 2 threads.
void BM_RenderSr3000(benchmark::State& state) {
  fusion::RenderOptions options;
  options.resolution_m = kResolutionM;
  options.threads = static_cast<unsigned>(state.range(0));
  RenderSr3000Frames(state, kStationaryFrames, options);
}
BENCHMARK(BM_RenderSr3000)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond)->UseRealTime();

// The same at fusiond's default map settings (5 cm voxels, rays to 9 m), one thread, for a
// grid of 1 frame (the first render of a period) and of 30.
void BM_RenderSr3000ServiceDefaults(benchmark::State& state) {
  fusion::RenderOptions options;
  options.resolution_m = 0.05;
  options.max_range_m = 9.0;
  RenderSr3000Frames(state, static_cast<std::size_t>(state.range(0)), options);
}
BENCHMARK(BM_RenderSr3000ServiceDefaults)
    ->Arg(1)
    ->Arg(kStationaryFrames)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

// Rendering and fusing a 30-frame SR-3000 period into a 2 cm world map
// (re-render of the same period: replaces the sensor's live contribution).
void BM_RenderAndFuseSr3000(benchmark::State& state) {
  const Fixture& f = SharedFixture();
  fusion::WorldMap map(MapOptions());
  (void)map.AddSensor("sr", f.sr.spec);
  for (const auto& cloud : f.frames) {
    (void)map.Integrate("sr", f.sr.T_world_sensor, cloud.xyz.data(), cloud.size(),
                        cloud.beyond_range);
  }
  fusion::FuseStats stats;
  for (auto _ : state) {
    benchmark::DoNotOptimize(map.Render("sr", &stats));
  }
  state.counters["map_leaves"] = static_cast<double>(map.tree().getNumLeafNodes());
  state.counters["rays"] = static_cast<double>(stats.render.rays_traced);
  state.counters["segments"] = static_cast<double>(stats.render.segments);
}
BENCHMARK(BM_RenderAndFuseSr3000)->Unit(benchmark::kMillisecond);

// Fusing into an empty map (first render of a period: every voxel is new to the
// octree).
void BM_RenderAndFuseSr3000IntoEmptyMap(benchmark::State& state) {
  const Fixture& f = SharedFixture();
  for (auto _ : state) {
    state.PauseTiming();
    auto map = std::make_unique<fusion::WorldMap>(MapOptions());
    (void)map->AddSensor("sr", f.sr.spec);
    for (const auto& cloud : f.frames) {
      (void)map->Integrate("sr", f.sr.T_world_sensor, cloud.xyz.data(), cloud.size(),
                           cloud.beyond_range);
    }
    state.ResumeTiming();
    benchmark::DoNotOptimize(map->Render("sr"));
    state.PauseTiming();
    map.reset();
    state.ResumeTiming();
  }
}
BENCHMARK(BM_RenderAndFuseSr3000IntoEmptyMap)->Unit(benchmark::kMillisecond);

// Stationary workflow: 30 SR-3000 frames integrated, then one render + fuse.
void BM_StationaryOurs(benchmark::State& state) {
  const Fixture& f = SharedFixture();
  for (auto _ : state) {
    fusion::WorldMap map(MapOptions());
    (void)map.AddSensor("sr", f.sr.spec);
    for (const auto& cloud : f.frames) {
      (void)map.Integrate("sr", f.sr.T_world_sensor, cloud.xyz.data(), cloud.size(),
                          cloud.beyond_range);
    }
    (void)map.Render("sr");
    benchmark::DoNotOptimize(map.version());
  }
}
BENCHMARK(BM_StationaryOurs)->Unit(benchmark::kMillisecond);

// The same 30 frames inserted into OctoMap at 2 cm (insertPointCloud, default
// sensor model).
void BM_StationaryOctoMap(benchmark::State& state) {
  const Fixture& f = SharedFixture();
  for (auto _ : state) {
    octomap::OcTree tree(kResolutionM);
    for (const auto& cloud : f.frames) {
      fusion::sim::InsertIntoOctoMap(cloud, f.sr.T_world_sensor, f.sr.spec.r_max_m, &tree);
    }
    benchmark::DoNotOptimize(tree.size());
  }
}
BENCHMARK(BM_StationaryOctoMap)->Unit(benchmark::kMillisecond)->Iterations(1);

// Moving sensor, per frame: every frame has a new pose, so each frame is
// integrated into a fresh beam grid, rendered and fused (commit of the previous
// period included).
void BM_MovingPerFrameOurs(benchmark::State& state) {
  const Fixture& f = SharedFixture();
  fusion::WorldMap map(MapOptions());
  (void)map.AddSensor("sr", f.sr.spec);
  std::size_t i = 0;
  fusion::FuseStats stats;
  for (auto _ : state) {
    const auto& cloud = f.frames[i % f.frames.size()];
    Eigen::Isometry3d T = f.sr.T_world_sensor;
    T.translation().y() += 0.05 * static_cast<double>(i % 2);  // beyond the 1 cm tolerance
    ++i;
    (void)map.Integrate("sr", T, cloud.xyz.data(), cloud.size(), cloud.beyond_range);
    (void)map.Render("sr", &stats);
  }
  state.counters["rays"] = static_cast<double>(stats.render.rays_traced);
  state.counters["segments"] = static_cast<double>(stats.render.segments);
  state.counters["voxels"] = static_cast<double>(stats.render.voxels);
}
BENCHMARK(BM_MovingPerFrameOurs)->Unit(benchmark::kMillisecond);

void BM_MovingPerFrameOctoMap(benchmark::State& state) {
  const Fixture& f = SharedFixture();
  octomap::OcTree tree(kResolutionM);
  std::size_t i = 0;
  for (auto _ : state) {
    const auto& cloud = f.frames[i % f.frames.size()];
    Eigen::Isometry3d T = f.sr.T_world_sensor;
    T.translation().y() += 0.05 * static_cast<double>(i % 2);
    ++i;
    fusion::sim::InsertIntoOctoMap(cloud, T, f.sr.spec.r_max_m, &tree);
  }
}
BENCHMARK(BM_MovingPerFrameOctoMap)->Unit(benchmark::kMillisecond);

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
