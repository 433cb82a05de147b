// The paper's Fig. 5 experiment as reusable pieces (tests, benchmarks, the
// accuracy report): sensor runs, simulated frames, and the OctoMap baseline fed
// with the same clouds.
#pragma once

#include <octomap/OcTree.h>

#include <Eigen/Geometry>
#include <memory>
#include <string>
#include <vector>

#include "fusion/core/sensor.h"
#include "fusion/core/world_map.h"
#include "fusion/sim/ground_truth.h"
#include "fusion/sim/simulator.h"

namespace fusion::sim {

// One sensor standing still for a number of frames.
struct SensorRun {
  std::string id;
  SensorSpec spec;
  Eigen::Isometry3d T_world_sensor = Eigen::Isometry3d::Identity();
  SimOptions sim;
  int frames = 1;
};

struct PaperRunOptions {
  int sr_frames = 30;
  int stereo_frames = 15;
  // The stereo camera's 640 x 480 pixels are simulated and mapped as 160 x 120
  // beams (same field of view): each beam stands for a 4 x 4 pixel block.
  int stereo_cols = 160;
  int stereo_rows = 120;
  std::uint64_t seed = 7;
};

// "sr3000" at the origin and "stoc" 25 mm left, 80 mm down, both looking along
// +x at the board of PaperBoardScene(). Stereo needs texture (so it does not
// see the floor) and has no beyond-range returns (r_max = inf).
[[nodiscard]] std::vector<SensorRun> PaperSensorRuns(const PaperRunOptions& options = {});

// Frames of one run, simulated in order with the run's seed.
[[nodiscard]] std::vector<OrganizedCloud> SimulateRun(const Scene& scene, const SensorRun& run);

// The OctoMap baseline: inserts one cloud with OcTree::insertPointCloud
// (default sensor model), origin = sensor position. Beyond-range points become
// rays cleared up to r_max.
void InsertIntoOctoMap(const OrganizedCloud& cloud, const Eigen::Isometry3d& T_world_sensor,
                       double r_max_m, octomap::OcTree* tree);

// Labelling views of the runs (noise-free rays, same visibility rules as the
// simulator).
[[nodiscard]] std::vector<View> ViewsOf(const std::vector<SensorRun>& runs);

// Our pipeline for stationary runs: every frame of every run integrated into
// its sensor's beam grid, then one render per sensor fused into the world map.
[[nodiscard]] std::unique_ptr<WorldMap> BuildForwardModelMap(
    const std::vector<SensorRun>& runs, const std::vector<std::vector<OrganizedCloud>>& frames,
    const WorldMapOptions& options);
// The baseline: every frame of every run inserted into one OcTree with default
// parameters.
[[nodiscard]] std::unique_ptr<octomap::OcTree> BuildOctoMap(
    const std::vector<SensorRun>& runs, const std::vector<std::vector<OrganizedCloud>>& frames,
    double resolution_m);

}  // namespace fusion::sim
