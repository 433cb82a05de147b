// Dynamic scenarios: the run, the trail of an object, the scenes.
#include "fusion/sim/dynamic_scenario.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <unordered_map>

#include "fusion/core/beam_tessellation.h"
#include "fusion/sim/ground_truth.h"
#include "fusion/sim/scene.h"
#include "fusion/sim/simulator.h"

namespace fusion::sim {
namespace {

constexpr const char* kPaperScene =
    "rect board 1.75 0 0.2   0 1 0   0 0 1   1.2 1.0\n"
    "rect floor 2.0 0 -0.41  1 0 0   0 1 0   4 4 untextured\n";

// The objects of `scene` that `keep` accepts (rectangles and boxes alike).
template <class Keep>
Scene Filtered(const Scene& scene, Keep keep) {
  Scene kept;
  for (const Rectangle& r : scene.rectangles()) {
    if (keep(r)) kept.AddRectangle(r);
  }
  for (const Box& b : scene.boxes()) {
    if (keep(b)) kept.AddBox(b);
  }
  return kept;
}

// One voxel the object held: the last frame it did, and frame by frame whether the map called
// it occupied (bit 0) and whether the sensor could see it (bit 1).
struct HeldVoxel {
  int last_held = -1;
  std::vector<std::uint8_t> seen;  // per frame
};
constexpr std::uint8_t kOccupied = 1;
constexpr std::uint8_t kVisible = 2;

// Whether the sensor at T_world_sensor sees the point: inside a beam and its range, and no
// surface of the scene as it is now lies more than a voxel in front of it.
bool Visible(const Scene& now, const BeamTessellation& beams, const SensorSpec& spec,
             const Eigen::Isometry3d& T_world_sensor, const Eigen::Vector3d& p_world,
             double voxel_m) {
  const Eigen::Vector3d p_sensor = T_world_sensor.inverse() * p_world;
  const double range_m = p_sensor.norm();
  if (!(range_m > spec.r_min_m && range_m < spec.r_max_m) || !beams.BeamOf(p_sensor)) {
    return false;
  }
  const Eigen::Vector3d origin = T_world_sensor.translation();
  return !now.Raycast(origin, (p_world - origin) / range_m, range_m - voxel_m).has_value();
}

// Marks the voxels whose centres lie inside the box (at least a voxel from every static
// surface) as held at `frame`.
void MarkHeld(
    const Box& box, const Scene& still, const octomap::OcTree& tree, int frame, int frames,
    std::unordered_map<octomap::OcTreeKey, HeldVoxel, octomap::OcTreeKey::KeyHash>* held) {
  const double res = tree.getResolution();
  const Eigen::Matrix3d R = box.T_world_box.rotation();
  const Eigen::Vector3d reach = R.cwiseAbs() * box.half_extents_m;
  const Eigen::Vector3d lo = box.T_world_box.translation() - reach;
  const Eigen::Vector3d hi = box.T_world_box.translation() + reach;
  const octomap::OcTreeKey k_lo = tree.coordToKey(lo.x(), lo.y(), lo.z());
  const octomap::OcTreeKey k_hi = tree.coordToKey(hi.x(), hi.y(), hi.z());
  const Eigen::Isometry3d T_box_world = box.T_world_box.inverse();
  for (unsigned x = k_lo[0]; x <= k_hi[0]; ++x) {
    for (unsigned y = k_lo[1]; y <= k_hi[1]; ++y) {
      for (unsigned z = k_lo[2]; z <= k_hi[2]; ++z) {
        const octomap::OcTreeKey key(static_cast<octomap::key_type>(x),
                                     static_cast<octomap::key_type>(y),
                                     static_cast<octomap::key_type>(z));
        const octomap::point3d c = tree.keyToCoord(key);
        const Eigen::Vector3d centre(c.x(), c.y(), c.z());
        const Eigen::Vector3d in_box = T_box_world * centre;
        if ((in_box.cwiseAbs() - box.half_extents_m).maxCoeff() > 0.0) continue;
        if (still.DistanceToSurface(centre) < res) continue;
        HeldVoxel& v = (*held)[key];
        if (v.seen.empty()) v.seen.assign(static_cast<std::size_t>(frames), 0);
        v.last_held = frame;
      }
    }
  }
}

const Box* FindBox(const Scene& scene, const std::string& name) {
  for (const Box& b : scene.boxes()) {
    if (b.name == name) return &b;
  }
  return nullptr;
}

}  // namespace

double DynamicResult::TrailAt(int lag) const {
  if (lag < 0 || static_cast<std::size_t>(lag) >= trail_by_lag.size()) return -1.0;
  return trail_by_lag[static_cast<std::size_t>(lag)];
}

int DynamicResult::ClearFrames(double fraction) const {
  int clear = -1;
  for (std::size_t lag = trail_by_lag.size(); lag-- > 1;) {
    const double f = trail_by_lag[lag];
    if (f < 0.0) continue;
    if (f > fraction) break;
    clear = static_cast<int>(lag);
  }
  return clear;
}

DynamicResult RunDynamicScenario(const DynamicScenario& scenario, const WorldMapOptions& options) {
  std::string error;
  std::optional<Scene> scene = ParseScene(scenario.scene, &error);
  if (!scene) throw std::invalid_argument("scenario " + scenario.name + ": " + error);
  if (scenario.without_object) {
    scene = Filtered(*scene, [&](const auto& o) { return o.name != scenario.object; });
  }
  const Scene still = Filtered(*scene, [](const auto& o) { return o.motion.IsStatic(); });
  if (scenario.sensor_path.empty()) throw std::invalid_argument("scenario has no sensor path");
  Motion sensor;
  sensor.path = scenario.sensor_path;

  WorldMap map(options);
  if (map.AddSensor("sensor", scenario.spec) != MapStatus::kOk) {
    throw std::invalid_argument("scenario " + scenario.name + ": sensor refused");
  }
  SimOptions sim;
  sim.seed = scenario.seed;
  RangeSimulator simulator(*scene, scenario.spec, sim);
  DynamicResult result;
  result.frames = static_cast<int>(std::lround(scenario.duration_s * scenario.frame_rate_hz));
  std::unordered_map<octomap::OcTreeKey, HeldVoxel, octomap::OcTreeKey::KeyHash> held;
  const BeamTessellation beams(scenario.spec);
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  for (int f = 0; f < result.frames; ++f) {
    const double t_s = f / scenario.frame_rate_hz;
    pose = ForwardLookingPose(sensor.CentreAt(t_s, Eigen::Vector3d::Zero()));
    const OrganizedCloud cloud = simulator.Capture(pose, t_s);
    IntegrationStats stats;
    if (map.Integrate("sensor", pose, cloud.xyz.data(), cloud.size(), cloud.beyond_range, &stats) !=
            MapStatus::kOk ||
        map.Render("sensor") != MapStatus::kOk) {
      throw std::runtime_error("scenario " + scenario.name + ": integration failed");
    }
    result.changes_detected += stats.changes_detected;
    result.beam_readings += stats.updated + stats.beyond_range;
    const Scene now = scene->At(t_s);
    if (const Box* box = FindBox(now, scenario.object)) {
      MarkHeld(*box, still, map.tree(), f, result.frames, &held);
    }
    const octomap::OcTree& tree = map.tree();
    for (auto& [key, voxel] : held) {
      const octomap::OcTreeNode* node = tree.search(key);
      const octomap::point3d c = tree.keyToCoord(key);
      std::uint8_t& seen = voxel.seen[static_cast<std::size_t>(f)];
      seen = node != nullptr && tree.isNodeOccupied(node) ? kOccupied : 0;
      if (Visible(now, beams, scenario.spec, pose, Eigen::Vector3d(c.x(), c.y(), c.z()),
                  options.resolution_m)) {
        seen |= kVisible;
      }
    }
  }
  // The trail: voxels occupied while held; their verdicts lag by lag after being vacated, where
  // the sensor could see them.
  std::vector<std::size_t> occupied(static_cast<std::size_t>(result.frames), 0);
  std::vector<std::size_t> pairs(static_cast<std::size_t>(result.frames), 0);
  for (const auto& [key, voxel] : held) {
    const auto last = static_cast<std::size_t>(voxel.last_held);
    if (std::none_of(voxel.seen.begin(), voxel.seen.begin() + last + 1,
                     [](std::uint8_t s) { return (s & kOccupied) != 0; })) {
      continue;
    }
    ++result.trail_voxels;
    for (std::size_t f = last + 1; f < voxel.seen.size(); ++f) {
      if ((voxel.seen[f] & kVisible) == 0) continue;
      ++pairs[f - last];
      occupied[f - last] += voxel.seen[f] & kOccupied;
    }
  }
  result.trail_by_lag.assign(pairs.size(), -1.0);
  for (std::size_t lag = 1; lag < pairs.size(); ++lag) {
    if (pairs[lag] > 0) result.trail_by_lag[lag] = static_cast<double>(occupied[lag]) / pairs[lag];
  }
  const VoxelLabels labels =
      LabelVoxels(still, {View{scenario.spec, pose, true, false}}, options.resolution_m);
  result.static_accuracy = EvaluateMap(map.tree(), labels, SurfaceDistance(still));
  return result;
}

DynamicScenario CrateRemovedScenario(const SensorSpec& spec, bool moving) {
  DynamicScenario s;
  s.name = moving ? "crate removed, sensor driving 0.3 m/s" : "crate removed, sensor still";
  s.scene = std::string(kPaperScene) + "box crate 1.3 0 0.1  0.2 0.4 0.4  until 1\n";
  s.object = "crate";
  s.spec = spec;
  s.duration_s = 2.0;
  if (moving) {
    s.sensor_path = {{0.0, Eigen::Vector3d(0.0, -0.3, 0.0)}, {2.0, Eigen::Vector3d(0.0, 0.3, 0.0)}};
  } else {
    s.sensor_path = {{0.0, Eigen::Vector3d::Zero()}};
  }
  return s;
}

DynamicScenario WalkerScenario(const SensorSpec& spec, bool moving) {
  DynamicScenario s;
  s.name = moving ? "person walking 1 m/s, sensor driving 0.3 m/s"
                  : "person walking 1 m/s, sensor still";
  s.scene = std::string(kPaperScene) +
            "box person 1.2 1.0 0.45  0.4 0.3 1.7  path 0 1.2 1.0 0.45  2 1.2 -1.0 0.45  until 2\n";
  s.object = "person";
  s.spec = spec;
  s.duration_s = 3.2;
  if (moving) {
    s.sensor_path = {{0.0, Eigen::Vector3d(0.0, 0.3, 0.0)},
                     {3.2, Eigen::Vector3d(0.0, -0.66, 0.0)}};
  } else {
    s.sensor_path = {{0.0, Eigen::Vector3d::Zero()}};
  }
  return s;
}

}  // namespace fusion::sim
