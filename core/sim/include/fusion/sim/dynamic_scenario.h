// Dynamic scenarios (a world that changes, docs/mapping.md): a sensor, standing still or moving,
// watches a scene in which one object is taken away or walks through, and the map is asked how
// long the object's voxels stay occupied once it has left them, what the static scene keeps,
// and how often a beam of it restarts (change detection).
//
// The trail of an object: the voxels its volume held at some frame (centres inside the box,
// more than a voxel from every static surface) that the map called occupied while it held
// them. Each such voxel is vacated at the last frame the object held it; `lag` frames later it
// is part of the trail if the map still calls it occupied. TrailAt(lag) is the occupied
// fraction over every (voxel, frame) pair that lies `lag` frames after the voxel was vacated
// and in which the sensor could see the voxel (inside its field of view and range, no surface
// in front of it): what the sensor never sees again it cannot clear.
#pragma once

#include <Eigen/Geometry>
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "fusion/core/accuracy.h"
#include "fusion/core/sensor.h"
#include "fusion/core/world_map.h"

namespace fusion::sim {

struct DynamicScenario {
  std::string name;
  std::string scene;   // scene file text (scene.h), dynamic objects included
  std::string object;  // the box whose trail is followed
  SensorSpec spec;
  // Sensor positions over scene time (linear in between, held outside), looking along +x
  // (ForwardLookingPose); one entry: a sensor that stands still.
  std::vector<std::pair<double, Eigen::Vector3d>> sensor_path;
  double frame_rate_hz = 30.0;
  double duration_s = 3.0;
  std::uint64_t seed = 1;
  // Run the scene without the object: the static baseline, whose beam restarts are false
  // alarms.
  bool without_object = false;
};

struct DynamicResult {
  int frames = 0;
  std::size_t trail_voxels = 0;  // voxels the object held that the map ever called occupied
  // trail_by_lag[L]: occupied fraction of the trail L frames after being vacated (-1: no pair)
  std::vector<double> trail_by_lag;
  std::uint64_t changes_detected = 0;  // beams restarted, whole run
  std::uint64_t beam_readings = 0;     // readings integrated (updated + beyond range)
  // The final map against the static scene as the sensor's last view labels it.
  AccuracyReport static_accuracy;

  // The first lag at which the trail is at most `fraction` occupied and stays so for every
  // later lag measured; -1 if never.
  [[nodiscard]] int ClearFrames(double fraction = 0.05) const;
  [[nodiscard]] double TrailAt(int lag) const;
};

// Runs the scenario with the map's options: every frame integrated (a moving sensor starts a
// period per pose) and rendered. The map resolution is options.resolution_m.
[[nodiscard]] DynamicResult RunDynamicScenario(const DynamicScenario& scenario,
                                               const WorldMapOptions& options);

// The scenarios of the issue, on the paper's board and floor (PaperBoardScene) with `spec`
// (the SR-3000 or a coarser tessellation of it): a crate taken away in front of a sensor at a
// fixed pose, the same while the sensor drives sideways at 0.3 m/s, and a person-sized box
// walking across the view at 1 m/s (still sensor).
[[nodiscard]] DynamicScenario CrateRemovedScenario(const SensorSpec& spec, bool moving);
[[nodiscard]] DynamicScenario WalkerScenario(const SensorSpec& spec, bool moving = false);

}  // namespace fusion::sim
