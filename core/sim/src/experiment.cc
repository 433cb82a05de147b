#include "fusion/sim/experiment.h"

#include <cmath>

#include "fusion/sim/scene.h"

namespace fusion::sim {

std::vector<SensorRun> PaperSensorRuns(const PaperRunOptions& options) {
  std::vector<SensorRun> runs;
  SensorRun sr;
  sr.id = "sr3000";
  sr.spec = *SensorPreset("sr3000");
  sr.T_world_sensor = ForwardLookingPose(Eigen::Vector3d::Zero());
  sr.sim.seed = options.seed;
  sr.frames = options.sr_frames;
  runs.push_back(sr);
  SensorRun stereo;
  stereo.id = "stoc";
  stereo.spec = WithTessellation(*SensorPreset("stoc"), options.stereo_cols, options.stereo_rows);
  stereo.T_world_sensor =
      ForwardLookingPose(Eigen::Vector3d(0.0, PaperSetup::kStereoLeftM, -PaperSetup::kStereoDownM));
  stereo.sim.seed = options.seed + 1;
  stereo.sim.require_texture = true;
  stereo.sim.flag_beyond_range = false;
  stereo.frames = options.stereo_frames;
  runs.push_back(stereo);
  return runs;
}

std::vector<OrganizedCloud> SimulateRun(const Scene& scene, const SensorRun& run) {
  RangeSimulator simulator(scene, run.spec, run.sim);
  std::vector<OrganizedCloud> frames;
  frames.reserve(static_cast<std::size_t>(run.frames));
  for (int i = 0; i < run.frames; ++i) frames.push_back(simulator.Capture(run.T_world_sensor));
  return frames;
}

void InsertIntoOctoMap(const OrganizedCloud& cloud, const Eigen::Isometry3d& T_world_sensor,
                       double r_max_m, octomap::OcTree* tree) {
  octomap::Pointcloud points;
  points.reserve(cloud.size());
  const Eigen::Vector3d origin = T_world_sensor.translation();
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    const float* p = &cloud.xyz[3 * i];
    if (!std::isfinite(p[0]) || !std::isfinite(p[1]) || !std::isfinite(p[2])) continue;
    Eigen::Vector3d p_sensor(p[0], p[1], p[2]);
    // Beyond-range: an endpoint past max range, so OctoMap clears the ray up to
    // r_max only.
    if (cloud.beyond_range[i] != 0) p_sensor *= (r_max_m + 1.0) / p_sensor.norm();
    const Eigen::Vector3d q = T_world_sensor * p_sensor;
    points.push_back(static_cast<float>(q.x()), static_cast<float>(q.y()),
                     static_cast<float>(q.z()));
  }
  tree->insertPointCloud(
      points,
      octomap::point3d(static_cast<float>(origin.x()), static_cast<float>(origin.y()),
                       static_cast<float>(origin.z())),
      r_max_m);
}

}  // namespace fusion::sim

namespace fusion::sim {

std::vector<View> ViewsOf(const std::vector<SensorRun>& runs) {
  std::vector<View> views;
  for (const SensorRun& run : runs) {
    View view;
    view.spec = run.spec;
    view.T_world_sensor = run.T_world_sensor;
    view.beyond_range_observed = run.sim.flag_beyond_range;
    view.require_texture = run.sim.require_texture;
    views.push_back(view);
  }
  return views;
}

std::unique_ptr<WorldMap> BuildForwardModelMap(
    const std::vector<SensorRun>& runs, const std::vector<std::vector<OrganizedCloud>>& frames,
    const WorldMapOptions& options) {
  auto map = std::make_unique<WorldMap>(options);
  for (std::size_t r = 0; r < runs.size(); ++r) {
    (void)map->AddSensor(runs[r].id, runs[r].spec);
    for (const OrganizedCloud& cloud : frames[r]) {
      (void)map->Integrate(runs[r].id, runs[r].T_world_sensor, cloud.xyz.data(), cloud.size(),
                           cloud.beyond_range);
    }
    (void)map->Render(runs[r].id);
  }
  return map;
}

std::unique_ptr<octomap::OcTree> BuildOctoMap(
    const std::vector<SensorRun>& runs, const std::vector<std::vector<OrganizedCloud>>& frames,
    double resolution_m) {
  auto tree = std::make_unique<octomap::OcTree>(resolution_m);
  for (std::size_t r = 0; r < runs.size(); ++r) {
    for (const OrganizedCloud& cloud : frames[r]) {
      InsertIntoOctoMap(cloud, runs[r].T_world_sensor, runs[r].spec.r_max_m, tree.get());
    }
  }
  return tree;
}

}  // namespace fusion::sim
