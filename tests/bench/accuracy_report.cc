// Prints the accuracy table of issue 4: our forward-model map vs OctoMap on the
// same simulated clouds of the paper's experiment (Fig. 5), at the same
// resolution.
//
//   accuracy_report [resolution_m]
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "fusion/core/accuracy.h"
#include "fusion/core/planes.h"
#include "fusion/core/world_map.h"
#include "fusion/sim/experiment.h"
#include "fusion/sim/ground_truth.h"
#include "fusion/sim/scene.h"
#include "fusion/sim/simulator.h"

namespace {

using fusion::AccuracyReport;
using Clock = std::chrono::steady_clock;

void PrintRow(const std::string& scenario, const std::string& method, const AccuracyReport& r,
              double seconds) {
  std::printf("| %s | %s | %.3f | %.3f | %.3f | %.3f | %.4f | %.1f | %.3f | %.2f |\n",
              scenario.c_str(), method.c_str(), r.precision, r.surface_precision, r.recall,
              r.free_accuracy, r.brier, 1000.0 * r.mean_surface_error_m, r.unknown_fraction,
              seconds);
}

double Seconds(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

// A table's row group: the sensor runs (indices into the paper's runs) mapped together.
struct Scenario {
  std::string name;
  std::vector<std::size_t> runs;
};

// A way of building our map: the fusion rule across sensors and the combination within one.
struct Variant {
  std::string name;
  fusion::FusionRule rule;
  fusion::VoxelCombine combine;
};

// The three voxel combinations with Eq. 16; with more than one sensor also the max and
// De Morgan rules.
std::vector<Variant> VariantsFor(const Scenario& sc) {
  std::vector<Variant> variants = {
      {"ours, mean log-odds, Eq. 16", fusion::FusionRule::kIndependentOpinionPool,
       fusion::VoxelCombine::kWeightedMeanLogOdds},
      {"ours, max log-odds, Eq. 16", fusion::FusionRule::kIndependentOpinionPool,
       fusion::VoxelCombine::kMaxLogOdds},
      {"ours, pooled log-odds, Eq. 16", fusion::FusionRule::kIndependentOpinionPool,
       fusion::VoxelCombine::kIndependentPool},
  };
  if (sc.runs.size() > 1) {
    variants.push_back({"ours, mean log-odds, max rule", fusion::FusionRule::kMax,
                        fusion::VoxelCombine::kWeightedMeanLogOdds});
    variants.push_back({"ours, mean log-odds, De Morgan", fusion::FusionRule::kDeMorgan,
                        fusion::VoxelCombine::kWeightedMeanLogOdds});
  }
  return variants;
}

// One row per variant of our map and one for OctoMap, each evaluated against the voxels the
// scenario's noise-free rays label.
void PrintScenarioRows(const Scenario& sc, const fusion::sim::Scene& scene,
                       const std::vector<fusion::sim::SensorRun>& all_runs,
                       const std::vector<std::vector<fusion::sim::OrganizedCloud>>& all_frames,
                       double resolution_m) {
  std::vector<fusion::sim::SensorRun> runs;
  std::vector<std::vector<fusion::sim::OrganizedCloud>> frames;
  for (std::size_t i : sc.runs) {
    runs.push_back(all_runs[i]);
    frames.push_back(all_frames[i]);
  }
  const fusion::VoxelLabels labels =
      fusion::sim::LabelVoxels(scene, fusion::sim::ViewsOf(runs), resolution_m);
  const auto distance = fusion::sim::SurfaceDistance(scene);
  for (const Variant& v : VariantsFor(sc)) {
    fusion::WorldMapOptions options;
    options.resolution_m = resolution_m;
    options.rule = v.rule;
    options.render.combine = v.combine;
    const auto start = Clock::now();
    const auto map = fusion::sim::BuildForwardModelMap(runs, frames, options);
    const double seconds = Seconds(start);
    PrintRow(sc.name, v.name, fusion::EvaluateMap(map->tree(), labels, distance), seconds);
  }
  const auto start = Clock::now();
  const auto octomap_tree = fusion::sim::BuildOctoMap(runs, frames, resolution_m);
  const double seconds = Seconds(start);
  PrintRow(sc.name, "OctoMap insertPointCloud",
           fusion::EvaluateMap(*octomap_tree, labels, distance), seconds);
}

// A sensor's drive at 30 Hz: a constant velocity (world frame) and turn about the vertical.
struct MovingDrive {
  std::string name;
  Eigen::Vector3d velocity_mps;
  double yaw_rate_degps = 0.0;
  int frames = 30;
};

// The drive's poses (each a one-frame run, to label from) and one simulated cloud at each.
struct DriveFrames {
  std::vector<fusion::sim::SensorRun> poses;
  std::vector<fusion::sim::OrganizedCloud> clouds;
};

DriveFrames SimulateDrive(const fusion::sim::Scene& scene, const fusion::sim::SensorRun& run,
                          const MovingDrive& drive) {
  constexpr double kFrameRateHz = 30.0;
  fusion::sim::RangeSimulator simulator(scene, run.spec, run.sim);
  DriveFrames out;
  for (int k = 0; k < drive.frames; ++k) {
    const double t_s = k / kFrameRateHz;
    fusion::sim::SensorRun at = run;
    at.T_world_sensor.translation() += drive.velocity_mps * t_s;
    at.T_world_sensor.linear() =
        Eigen::AngleAxisd(drive.yaw_rate_degps * t_s * M_PI / 180.0, Eigen::Vector3d::UnitZ())
            .toRotationMatrix() *
        run.T_world_sensor.linear();
    out.poses.push_back(at);
    out.clouds.push_back(simulator.Capture(at.T_world_sensor));
  }
  return out;
}

// A way of mapping a drive: how the frames share beam grids (the pose tolerance: frames within
// it of a period's first pose share its grid, their points moved into its frame) and the render.
struct MovingVariant {
  std::string name;
  double tolerance_m, tolerance_deg;
  fusion::RenderMethod method;
};

// A moving SR-3000, one cloud per pose, against the labels of every pose's noise-free rays: our
// map in each MovingVariant, then OctoMap's.
void PrintMovingRows(const fusion::sim::Scene& scene, const fusion::sim::SensorRun& run,
                     const MovingDrive& drive, double resolution_m) {
  const DriveFrames d = SimulateDrive(scene, run, drive);
  const std::vector<fusion::sim::SensorRun>& poses = d.poses;
  const std::vector<fusion::sim::OrganizedCloud>& clouds = d.clouds;
  const fusion::VoxelLabels labels =
      fusion::sim::LabelVoxels(scene, fusion::sim::ViewsOf(poses), resolution_m);
  const auto distance = fusion::sim::SurfaceDistance(scene);
  const std::string& name = drive.name;
  const double default_deg = fusion::WorldMapOptions::kDefaultPoseToleranceDeg;
  const double default_m = fusion::WorldMapOptions::kDefaultPoseToleranceM;
  const std::vector<MovingVariant> variants = {
      {"ours, default pose tolerance (" + std::to_string(std::lround(default_m * 100)) +
           " cm / " + std::to_string(std::lround(default_deg)) + " deg)",
       default_m, default_deg, fusion::RenderMethod::kProjective},
      {"ours, every frame its own period", 0.0, 0.0, fusion::RenderMethod::kProjective},
      {"ours, pose tolerance 1 cm / 1 deg", 0.01, 1.0, fusion::RenderMethod::kProjective},
      {"ours, pose tolerance 3 cm / 1 deg", 0.03, 1.0, fusion::RenderMethod::kProjective},
      {"ours, ray-traced render (the oracle), default tolerance", default_m, default_deg,
       fusion::RenderMethod::kRayTraced},
  };
  for (const MovingVariant& v : variants) {
    fusion::WorldMapOptions options;
    options.resolution_m = resolution_m;
    options.pose_tolerance_m = v.tolerance_m;
    options.pose_tolerance_rad = v.tolerance_deg * M_PI / 180.0;
    options.render.method = v.method;
    const auto start = Clock::now();
    fusion::WorldMap map(options);
    (void)map.AddSensor(run.id, run.spec);
    for (std::size_t k = 0; k < clouds.size(); ++k) {
      (void)map.Integrate(run.id, poses[k].T_world_sensor, clouds[k].xyz.data(), clouds[k].size(),
                          clouds[k].beyond_range);
    }
    (void)map.Commit(run.id);
    const double seconds = Seconds(start);
    PrintRow(name, v.name, fusion::EvaluateMap(map.tree(), labels, distance), seconds);
  }
  const auto start = Clock::now();
  octomap::OcTree tree(resolution_m);
  for (std::size_t k = 0; k < clouds.size(); ++k) {
    fusion::sim::InsertIntoOctoMap(clouds[k], poses[k].T_world_sensor, run.spec.r_max_m, &tree);
  }
  const double seconds = Seconds(start);
  PrintRow(name, "OctoMap insertPointCloud", fusion::EvaluateMap(tree, labels, distance), seconds);
}

// Planes of the fused map (paper Sec. V).
void PrintPlanesOfTheFusedMap(
    const std::vector<fusion::sim::SensorRun>& all_runs,
    const std::vector<std::vector<fusion::sim::OrganizedCloud>>& all_frames, double resolution_m) {
  fusion::WorldMapOptions options;
  options.resolution_m = resolution_m;
  const auto map = fusion::sim::BuildForwardModelMap(all_runs, all_frames, options);
  const auto start = Clock::now();
  const auto planes = fusion::DetectPlanes(map->tree());
  const double seconds = Seconds(start);
  std::printf(
      "\nPlanes of the fused map (Hough %.2f s): n . p = d, phi = normal "
      "azimuth, "
      "theta = polar angle\n\n| phi [deg] | theta [deg] | d [mm] | support "
      "voxels | rms "
      "[mm] |\n|---|---|---|---|---|\n",
      seconds);
  constexpr double kRadToDeg = 57.29577951308232;
  for (const auto& p : planes) {
    std::printf("| %.2f | %.2f | %.1f | %zu | %.1f |\n", p.phi_rad * kRadToDeg,
                p.theta_rad * kRadToDeg, p.distance_m * 1000.0, p.support_voxels, p.rms_m * 1000.0);
  }
}

}  // namespace

int main(int argc, char** argv) {
  const std::string arg = argc > 1 ? argv[1] : "0.02";
  char* end = nullptr;
  const double resolution_m = std::strtod(arg.c_str(), &end);
  if (argc > 2 || arg == "--help" || arg == "-h" || end == arg.c_str() || *end != '\0' ||
      !(resolution_m >= 0.005 && resolution_m <= 1.0)) {
    std::fprintf(arg == "--help" || arg == "-h" ? stdout : stderr,
                 "usage: accuracy_report [RESOLUTION_M]\n"
                 "  The simulator's accuracy table (our map against OctoMap on the paper's board\n"
                 "  scene; BENCHMARKS.md), voxels of RESOLUTION_M metres, 0.005..1 (default 0.02);\n"
                 "  then the SR-3000 on two drives (30 poses, one cloud each) and the fused map's\n"
                 "  planes.\n");
    return arg == "--help" || arg == "-h" ? 0 : 2;
  }
  const fusion::sim::Scene scene = fusion::sim::PaperBoardScene();
  const auto all_runs = fusion::sim::PaperSensorRuns();
  std::vector<std::vector<fusion::sim::OrganizedCloud>> all_frames;
  for (const auto& run : all_runs) all_frames.push_back(fusion::sim::SimulateRun(scene, run));

  const std::vector<Scenario> scenarios = {
      {"stereo (stoc 160x120, 15 frames)", {1}},
      {"SR-3000 (176x144, 30 frames)", {0}},
      {"fused SR-3000 + stereo", {0, 1}},
  };
  std::printf(
      "resolution %.3f m; labels: voxels crossed by noise-free rays (free) or "
      "holding a\n"
      "surface (occupied); p = 0.5 where a map has no node\n\n",
      resolution_m);
  std::printf(
      "| scenario | method | precision | precision (surface) | recall | free acc. | Brier | "
      "surface err. [mm] | unknown | time [s] |\n|---|---|---|---|---|---|---|---|---|---|\n");
  for (const Scenario& sc : scenarios)
    PrintScenarioRows(sc, scene, all_runs, all_frames, resolution_m);
  // bench_map's moving drive; then ahead towards the board, turning faster.
  const std::vector<MovingDrive> drives = {
      {"SR-3000 sideways 0.17 m/s, 4 deg/s (30 poses)", {0.0, 0.17, 0.0}, 4.0, 30},
      {"SR-3000 ahead 0.3 m/s, 10 deg/s (30 poses)", {0.3, 0.0, 0.0}, 10.0, 30},
  };
  for (const MovingDrive& drive : drives) PrintMovingRows(scene, all_runs[0], drive, resolution_m);
  PrintPlanesOfTheFusedMap(all_runs, all_frames, resolution_m);
  return 0;
}
