// TUM RGB-D fr2/pioneer_slam2 (10 Kinect frames, every pixel) mapped three ways, side by side:
//   1. through the service: fusion-import tum --stride 1 -> fusion-replay --fast --reliable ->
//      a fusiond process (127.0.0.1:0, private DDS domain, loopback DDS) with an explicit Kinect
//      sensor of one beam per pixel (640 x 480); timed from the replay's start until GetStats
//      clouds_in_map reaches the 10 clouds;
//   2. in process: the same recording fed to fusion::WorldMap (Integrate + Render per cloud),
//      with the sensor spec and map options converted from the same configuration file by the
//      service's own conversions;
//   3. OctoMap: octomap::OcTree::insertPointCloud of the same points (world frame, sensor
//      origin, max range = the Kinect's r_max).
// The import is timed separately. Prints a markdown table.
// Usage: tum_map_bench [--data DIR] [--resolution M] [--beams COLSxROWS] [--log-level LEVEL]
//                      [--timeout S] [--pose-tolerance M,DEG] [--render-threads N]
//                      [--model hand|kinect_v1]
//   --data: the TUM folder (default <repo>/../shared/data/tum_fr2_pioneer_slam2); absent: exit 0
//   --resolution: map voxel edge in metres (default 0.02); --beams: the Kinect's beam grid
//   (default 640x480, one beam per pixel; 160x120 gives each beam a 4 x 4 block of pixels, every
//   pixel still a reading of its beam, as the deployment does for the stereo camera);
//   --log-level: fusiond's (default warn;
//   other levels write its whole log to /tmp/tum_map_bench_fusiond.log); --timeout: seconds to
//   wait for the service's map (default 900); --render-threads: map.render_threads of both
//   maps (default: the service's, one fewer than the hardware threads); --model: the sensor,
//   hand (default: the hand-typed Kinect of e2e_tum_test.cc) or the kinect_v1 preset.
//
// The shared pieces live in tum_map_bench_*.h beside this file (tests/CMakeLists.txt makes one
// program of each .cc file here): _common (options, configuration, tools), _recording (the
// recording's frames), _service (way 1).
#include <octomap/OcTree.h>
#include <stdlib.h>

#include <Eigen/Geometry>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "fusion/core/world_map.h"
#include "tum_map_bench_common.h"
#include "tum_map_bench_recording.h"
#include "tum_map_bench_service.h"

namespace fusion::tum_map_bench {
namespace {

// ---- 2. ours in process --------------------------------------------------------------------

struct CoreTotals {
  fusion::IntegrationStats integration;
  std::size_t failures = 0;
  double integrate_s = 0;
  double render_s = 0;
};

void AddStats(const fusion::IntegrationStats& s, fusion::IntegrationStats* total) {
  total->updated += s.updated;
  total->beyond_range += s.beyond_range;
  total->missing += s.missing;
  total->rejected_nonfinite += s.rejected_nonfinite;
  total->rejected_outside_fov += s.rejected_outside_fov;
  total->changes_detected += s.changes_detected;
}

void IntegrateAndRender(fusion::WorldMap& map, const CoreSetup& setup, const Frame& frame,
                        CoreTotals* totals) {
  fusion::IntegrationStats stats;
  const Eigen::Isometry3d T = frame.T_world_sensor * setup.sensor.T_published_sensor;
  const auto t0 = Clock::now();
  const auto integrated = map.Integrate(kSensorId, T, frame.xyz.data(), frame.xyz.size() / 3,
                                        frame.beyond_range, &stats);
  totals->integrate_s += SecondsSince(t0);
  AddStats(stats, &totals->integration);
  if (integrated != fusion::MapStatus::kOk) {
    std::printf("  in process: Integrate: %s\n", fusion::MapStatusName(integrated));
    ++totals->failures;
    return;
  }
  const auto t1 = Clock::now();
  const auto rendered = map.Render(kSensorId);
  totals->render_s += SecondsSince(t1);
  if (rendered != fusion::MapStatus::kOk) {
    std::printf("  in process: Render: %s\n", fusion::MapStatusName(rendered));
    ++totals->failures;
  }
}

void PrintCoreCounters(const fusion::WorldMap& map, const CoreTotals& totals) {
  const auto& s = totals.integration;
  std::printf(
      "in-process counters: points updated %zu, beyond range %zu, missing %zu, rejected "
      "non-finite %zu, rejected outside the FOV %zu; failures %zu; Integrate (incl. committing "
      "the previous period when the pose moved) %.2f s, Render %.2f s\n",
      s.updated, s.beyond_range, s.missing, s.rejected_nonfinite, s.rejected_outside_fov,
      totals.failures, totals.integrate_s, totals.render_s);
  if (const auto c = map.Counters(kSensorId); c && map.beam_grid(kSensorId) != nullptr) {
    const double beam_clouds =
        static_cast<double>(map.beam_grid(kSensorId)->beam_count()) *
        static_cast<double>(std::max<std::uint64_t>(1, c->frames_integrated));
    std::printf(
        "  change detection: %zu beams restarted: %.2g per reading, %.2g per beam and cloud\n",
        s.changes_detected,
        static_cast<double>(s.changes_detected) /
            static_cast<double>(std::max<std::size_t>(1, s.updated + s.beyond_range)),
        static_cast<double>(s.changes_detected) / beam_clouds);
  }
  if (const auto c = map.Counters(kSensorId)) {
    std::printf(
        "  WorldMap counters: frames integrated %llu, renders %llu, commits %llu, "
        "pose moves %llu\n",
        (unsigned long long)c->frames_integrated, (unsigned long long)c->renders,
        (unsigned long long)c->commits, (unsigned long long)c->pose_moves);
  }
  std::printf("  WorldMap::MemoryBytes (history + working + published trees + live): %.1f MB\n",
              Megabytes(static_cast<double>(map.MemoryBytes())));
}

std::optional<Row> RunCore(const CoreSetup& setup, const std::vector<Frame>& frames) {
  std::printf(
      "in process: WorldMap resolution %.3f m, beam cell %.3f m, render threads %u, "
      "rule %d, %d x %d beams\n",
      setup.map.resolution_m, setup.map.beam_grid.cell_size_m, setup.map.render.threads,
      static_cast<int>(setup.map.rule), setup.sensor.spec.cols, setup.sensor.spec.rows);
  fusion::WorldMap map(setup.map);
  if (map.AddSensor(kSensorId, setup.sensor.spec) != fusion::MapStatus::kOk) {
    std::fprintf(stderr, "in process: AddSensor failed\n");
    return std::nullopt;
  }
  CoreTotals totals;
  const double cpu0_s = OwnCpuSeconds();
  const auto t0 = Clock::now();
  for (const auto& frame : frames) IntegrateAndRender(map, setup, frame, &totals);
  const double elapsed_s = SecondsSince(t0);
  const double cpu_s = OwnCpuSeconds() - cpu0_s;
  PrintCoreCounters(map, totals);
  const auto& tree = map.tree();
  return Row{"ours, in process (WorldMap Integrate + Render per cloud)", elapsed_s,
             tree.getNumLeafNodes(), static_cast<double>(tree.memoryUsage()), cpu_s};
}

// ---- 3. OctoMap ----------------------------------------------------------------------------

octomap::Pointcloud WorldCloud(const Frame& frame) {
  octomap::Pointcloud cloud;
  cloud.reserve(frame.xyz.size() / 3);
  for (std::size_t i = 0; i + 2 < frame.xyz.size(); i += 3) {
    const Eigen::Vector3d p(frame.xyz[i], frame.xyz[i + 1], frame.xyz[i + 2]);
    if (!p.allFinite()) continue;
    const Eigen::Vector3d w = frame.T_world_sensor * p;
    cloud.push_back(static_cast<float>(w.x()), static_cast<float>(w.y()),
                    static_cast<float>(w.z()));
  }
  return cloud;
}

// The world-frame clouds are built before the clock starts; only insertPointCloud is timed.
Row RunOctomap(const std::vector<Frame>& frames, double resolution_m) {
  std::vector<octomap::Pointcloud> clouds;
  std::vector<octomap::point3d> origins;
  for (const auto& frame : frames) {
    clouds.push_back(WorldCloud(frame));
    const Eigen::Vector3d o = frame.T_world_sensor.translation();
    origins.emplace_back(static_cast<float>(o.x()), static_cast<float>(o.y()),
                         static_cast<float>(o.z()));
  }
  octomap::OcTree tree(resolution_m);
  const double cpu0_s = OwnCpuSeconds();
  const auto t0 = Clock::now();
  for (std::size_t i = 0; i < clouds.size(); ++i)
    tree.insertPointCloud(clouds[i], origins[i], kKinectRMaxM);
  const double elapsed_s = SecondsSince(t0);
  const double cpu_s = OwnCpuSeconds() - cpu0_s;
  std::printf(
      "OctoMap: insertPointCloud (max range %.1f m, default sensor model, pruned as it "
      "goes), %zu nodes\n",
      kKinectRMaxM, tree.size());
  return Row{"OctoMap insertPointCloud", elapsed_s, tree.getNumLeafNodes(),
             static_cast<double>(tree.memoryUsage()), cpu_s};
}

// ---- report --------------------------------------------------------------------------------

void PrintTable(const std::vector<Row>& rows, const std::optional<Row>& octomap) {
  std::printf(
      "\n| method | time [s] | leaves | memory [MB] | OctoMap time / this time | "
      "CPU [s] |\n|---|---|---|---|---|---|\n");
  for (const auto& row : rows) {
    char ratio[32] = "-";
    if (octomap && row.method != octomap->method)
      std::snprintf(ratio, sizeof ratio, "%.2fx", octomap->time_s / row.time_s);
    std::printf("| %s | %.2f | %llu | %.1f | %s | %.2f |\n", row.method.c_str(), row.time_s,
                (unsigned long long)row.leaves, Megabytes(row.memory_bytes), ratio, row.cpu_s);
  }
  std::printf(
      "\ntime: wall clock. fusiond: from starting fusion-replay to GetStats clouds_in_map == all "
      "clouds (DDS discovery, transfer, integration, rendering, publication); in process: the "
      "Integrate + Render loop; OctoMap: the insertPointCloud loop (world-frame clouds built "
      "before). leaves / memory: getNumLeafNodes / memoryUsage of the (published) octree. CPU: "
      "fusiond's process (all threads) / this process during the same interval.\n");
}

std::optional<ToolRun> Import(const std::string& data_dir, const std::string& recording) {
  const ToolRun run = RunTool({kBinaryDir + "/clients/fusion-import", "tum", data_dir, "--stride",
                               "1", "--sensor-id", kSensorId, "-o", recording},
                              std::chrono::seconds(300));
  std::printf("import: fusion-import tum %s --stride 1 --sensor-id %s -o %s: exit %d, %.2f s\n%s",
              data_dir.c_str(), kSensorId.c_str(), recording.c_str(), run.exit_code, run.elapsed_s,
              run.output.c_str());
  if (run.exit_code != 0) return std::nullopt;
  return run;
}

void PrintFrames(const std::vector<Frame>& frames, const std::string& recording) {
  std::size_t points = 0, finite = 0;
  for (const auto& f : frames) {
    points += f.xyz.size() / 3;
    finite += FinitePoints(f);
  }
  std::printf(
      "recording %s: %.1f MB, %zu clouds of %u x %u, %zu pixels, %zu with a depth "
      "(finite points)\n",
      recording.c_str(), Megabytes(static_cast<double>(fs::file_size(recording))), frames.size(),
      frames.empty() ? 0 : frames[0].width, frames.empty() ? 0 : frames[0].height, points, finite);
}

bool ToolsPresent() {
  for (const char* tool :
       {"/service/fusiond", "/clients/fusion-import", "/clients/fusion-replay"}) {
    if (!fs::exists(kBinaryDir + tool)) {
      std::fprintf(stderr, "%s%s is missing: build it first\n", kBinaryDir.c_str(), tool);
      return false;
    }
  }
  return true;
}

int RunAll(const Options& options, const std::string& dir) {
  const std::string recording = dir + "/tum_stride1.frec";
  const auto import = Import(options.data_dir, recording);
  if (!import) return 1;
  const std::vector<Frame> frames = ReadFrames(recording);
  PrintFrames(frames, recording);
  if (frames.empty()) return 1;
  const std::string config_path = dir + "/fusiond.pbtxt";
  std::ofstream(config_path) << ConfigText(options);
  std::printf("configuration (fusiond and in process):\n\n```\n%s```\n\n",
              ConfigText(options).c_str());
  const auto setup = CoreSetupFromFile(config_path);
  if (!setup) return 1;

  std::printf("\n## 1. ours through the service\n\n");
  const auto service = RunService(config_path, recording, frames.size(), options);
  std::printf("\n## 2. ours in process\n\n");
  const auto core = RunCore(*setup, frames);
  std::printf("\n## 3. OctoMap\n\n");
  const Row octomap = RunOctomap(frames, options.resolution_m);

  std::vector<Row> rows;
  if (service) rows.push_back(*service);
  if (core) rows.push_back(*core);
  rows.push_back(octomap);
  const std::string sensor = options.model == "kinect_v1"
                                 ? "the kinect_v1 preset (640 x 480 pinhole beams)"
                                 : "the hand-typed Kinect, " + std::to_string(options.cols) +
                                       " x " + std::to_string(options.rows) + " beams";
  std::printf("\n## Results at %.3f m, %s (import, not compared: %.2f s)\n",
              options.resolution_m, sensor.c_str(), import->elapsed_s);
  PrintTable(rows, octomap);
  if (!service) std::printf("\n(the service row is missing: see section 1)\n");
  return service && core ? 0 : 1;
}

}  // namespace
}  // namespace fusion::tum_map_bench

namespace tmb = fusion::tum_map_bench;
using tmb::Clock;
namespace fs = std::filesystem;

int main(int argc, char** argv) {
  tmb::Options options;
  if (argc == 2 && std::string(argv[1]) == "--help") {
    std::printf("%s", tmb::kUsage);
    return 0;
  }
  if (!tmb::ParseArgs(argc, argv, &options)) return 2;
  std::printf(
      "# TUM fr2/pioneer_slam2, every pixel: fusiond vs. WorldMap vs. OctoMap\n\n"
      "command: %s\n\nload average at start: %s; hardware threads: %u\n\n",
      tmb::CommandLine(argc, argv).c_str(), tmb::LoadAverage().c_str(),
      std::thread::hardware_concurrency());
  if (!fs::exists(fs::path(options.data_dir) / "groundtruth.txt")) {
    std::printf(
        "TUM data missing: %s (see ../shared/data/README.md: tum_fr2_pioneer_slam2); "
        "give --data DIR. Nothing measured.\n",
        options.data_dir.c_str());
    return 0;
  }
  if (!tmb::ToolsPresent()) return 1;
  char dir_template[] = "/tmp/tum_map_bench_XXXXXX";
  const char* dir = mkdtemp(dir_template);
  if (dir == nullptr) return 1;
  const auto t0 = Clock::now();
  const int code = tmb::RunAll(options, dir);
  std::printf("\ntotal %.1f s; load average at end: %s\n", tmb::SecondsSince(t0),
              tmb::LoadAverage().c_str());
  fs::remove_all(dir);
  return code;
}
