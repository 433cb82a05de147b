// Beam-grid update speed and memory: one SR-3000 frame (176 x 144 beams, 1 mm cells over 7.5 m)
// on one core, dense reference vs unrolled linked list (ULL).
//
//   bench_beam --benchmark_min_time=0.2
//
// The dense grid at full size would take ~1.5 GB and seconds per frame, so it is measured on
// one row of beams (176) and scaled to the frame (counter frame_ms_scaled).
#include <benchmark/benchmark.h>

#include <cmath>
#include <random>
#include <vector>

#include "fusion/core/beam_grid.h"

namespace {

using fusion::BeamGrid;
using fusion::BeamGridOptions;
using fusion::BeamRepresentation;
using fusion::Reading;
using fusion::SensorSpec;

constexpr std::size_t kSrBeams = 176 * 144;
constexpr int kFrames = 8;

SensorSpec Sr3000Rows(int rows) {
  SensorSpec s = *fusion::SensorPreset("sr3000");
  s.rows = rows;
  return s;
}

BeamGridOptions Options(double cell_size_m, BeamRepresentation rep) {
  BeamGridOptions o;
  o.cell_size_m = cell_size_m;
  o.representation = rep;
  return o;
}

// A wall 3 m in front of the sensor, read with the SR-3000's own noise; every 50th point
// missing and every 100th beyond range, as real frames have.
std::vector<std::vector<Reading>> Frames(const BeamGrid& grid, int frames) {
  const SensorSpec& s = grid.spec();
  std::mt19937 rng(42);
  std::normal_distribution<double> unit(0.0, 1.0);
  std::vector<std::vector<Reading>> out(frames);
  for (int f = 0; f < frames; ++f) {
    out[f].resize(grid.beam_count());
    for (std::size_t b = 0; b < grid.beam_count(); ++b) {
      const double range = 3.0 / grid.tessellation().Direction(b).z();
      Reading r{Reading::Kind::kRange, s.q_mu(range) + s.q_sigma(range) * unit(rng)};
      if (b % 50 == 7) r.kind = Reading::Kind::kMissing;
      if (b % 100 == 13) r.kind = Reading::Kind::kBeyondRange;
      out[f][b] = r;
    }
  }
  return out;
}

std::vector<float> Cloud(const BeamGrid& grid, const std::vector<Reading>& frame) {
  std::vector<float> xyz;
  xyz.reserve(3 * frame.size());
  for (std::size_t b = 0; b < frame.size(); ++b) {
    const Eigen::Vector3d p = grid.tessellation().Direction(b) *
                              (frame[b].kind == Reading::Kind::kRange ? frame[b].range_m : 0.0);
    xyz.push_back(static_cast<float>(p.x()));
    xyz.push_back(static_cast<float>(p.y()));
    xyz.push_back(static_cast<float>(p.z()));
  }
  return xyz;
}

void Report(benchmark::State& state, const BeamGrid& grid, double beams_per_iteration,
            double scale_to_frame) {
  // kIsIterationInvariantRate | kInvert: seconds per (value * iteration); value = beams * 1e-9
  // gives nanoseconds per beam.
  state.counters["ns_per_beam"] =
      benchmark::Counter(beams_per_iteration * 1e-9, benchmark::Counter::kIsIterationInvariantRate |
                                                         benchmark::Counter::kInvert);
  state.counters["grid_MB"] = static_cast<double>(grid.MemoryBytes()) / 1e6;
  state.counters["grid_MB_frame_scaled"] =
      static_cast<double>(grid.MemoryBytes()) / 1e6 * scale_to_frame;
  state.SetItemsProcessed(static_cast<std::int64_t>(state.iterations() * beams_per_iteration));
}

// ULL, full frame through BeamGrid::UpdateEachBeam (readings already assigned to beams). The first
// kFrames frames (ROI explosion, allocation) run before timing: this is the steady state of a
// robot that stands still and keeps sampling.
void BM_UllFrameUpdate(benchmark::State& state) {
  BeamGrid grid(Sr3000Rows(static_cast<int>(state.range(0))),
                Options(0.001, BeamRepresentation::kUnrolledLinkedList));
  const auto frames = Frames(grid, kFrames);
  for (const auto& frame : frames) grid.UpdateEachBeam(frame);
  int f = 0;
  for (auto _ : state) {
    benchmark::DoNotOptimize(grid.UpdateEachBeam(frames[f++ % kFrames]));
    benchmark::ClobberMemory();
  }
  Report(state, grid, static_cast<double>(grid.beam_count()),
         static_cast<double>(kSrBeams) / static_cast<double>(grid.beam_count()));
}
// 144 rows = the full frame; 8 rows shows the same work with the grid in cache.
BENCHMARK(BM_UllFrameUpdate)->Arg(144)->Arg(8)->Unit(benchmark::kMillisecond);

// ULL, first frame on a fresh grid (every beam explodes its first ROI). Grid construction is
// excluded from the timing.
void BM_UllFirstFrame(benchmark::State& state) {
  BeamGrid grid(Sr3000Rows(144), Options(0.001, BeamRepresentation::kUnrolledLinkedList));
  const auto frames = Frames(grid, 1);
  for (auto _ : state) {
    state.PauseTiming();
    grid.Reset();
    state.ResumeTiming();
    benchmark::DoNotOptimize(grid.UpdateEachBeam(frames[0]));
    benchmark::ClobberMemory();
  }
  Report(state, grid, kSrBeams, 1.0);
}
BENCHMARK(BM_UllFirstFrame)->Unit(benchmark::kMillisecond);

// ULL, full frame as a point cloud through BeamGrid::Integrate (tessellation included).
void BM_UllFrameIntegrate(benchmark::State& state) {
  BeamGrid grid(Sr3000Rows(144), Options(0.001, BeamRepresentation::kUnrolledLinkedList));
  const auto frames = Frames(grid, kFrames);
  std::vector<std::vector<float>> clouds;
  for (const auto& frame : frames) clouds.push_back(Cloud(grid, frame));
  std::vector<std::uint8_t> beyond(kSrBeams, 0);
  for (std::size_t b = 0; b < kSrBeams; ++b) beyond[b] = b % 100 == 13 ? 1 : 0;
  for (const auto& cloud : clouds) grid.Integrate(cloud.data(), kSrBeams, beyond);
  int f = 0;
  for (auto _ : state) {
    const auto& cloud = clouds[f++ % kFrames];
    benchmark::DoNotOptimize(grid.Integrate(cloud.data(), kSrBeams, beyond));
  }
  Report(state, grid, kSrBeams, 1.0);
}
BENCHMARK(BM_UllFrameIntegrate)->Unit(benchmark::kMillisecond);

// Dense reference on one row of beams (176 of 25344), scaled to the frame.
void BM_DenseRowUpdate(benchmark::State& state) {
  BeamGrid grid(Sr3000Rows(1), Options(0.001, BeamRepresentation::kDense));
  const auto frames = Frames(grid, kFrames);
  int f = 0;
  for (auto _ : state) {
    const auto& frame = frames[f++ % kFrames];
    for (std::size_t b = 0; b < frame.size(); ++b) grid.Update(b, frame[b]);
    benchmark::ClobberMemory();
  }
  const double scale = static_cast<double>(kSrBeams) / static_cast<double>(grid.beam_count());
  Report(state, grid, static_cast<double>(grid.beam_count()), scale);
  state.counters["frame_ms_scaled"] = benchmark::Counter(
      1e-3 / scale, benchmark::Counter::kIsIterationInvariantRate | benchmark::Counter::kInvert);
}
BENCHMARK(BM_DenseRowUpdate)->Unit(benchmark::kMillisecond);

// Memory of whole SR-3000 grids: ULL at 1 mm after kFrames frames; dense measured at 20 mm
// cells (full grid) and extrapolated x20 to 1 mm (dense memory is linear in the cell count).
void BM_GridMemory(benchmark::State& state) {
  BeamGrid ull(Sr3000Rows(144), Options(0.001, BeamRepresentation::kUnrolledLinkedList));
  const std::size_t ull_fresh = ull.MemoryBytes();
  for (const auto& frame : Frames(ull, kFrames)) {
    for (std::size_t b = 0; b < frame.size(); ++b) ull.Update(b, frame[b]);
  }
  BeamGrid dense(Sr3000Rows(144), Options(0.020, BeamRepresentation::kDense));
  for (auto _ : state) benchmark::DoNotOptimize(ull.MemoryBytes() + dense.MemoryBytes());
  state.counters["ull_1mm_fresh_MB"] = static_cast<double>(ull_fresh) / 1e6;
  state.counters["ull_1mm_MB"] = static_cast<double>(ull.MemoryBytes()) / 1e6;
  state.counters["dense_20mm_MB"] = static_cast<double>(dense.MemoryBytes()) / 1e6;
  state.counters["dense_1mm_MB_extrapolated"] =
      static_cast<double>(dense.MemoryBytes()) / 1e6 * (7500.0 + 1.0) / (375.0 + 1.0);
}
BENCHMARK(BM_GridMemory)->Iterations(1);

}  // namespace

BENCHMARK_MAIN();
