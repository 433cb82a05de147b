// Range-sensor simulator: ray-casts a scene for a sensor's beam tessellation
// into an organized cloud with the sensor's own forward-model noise.
#pragma once

#include <Eigen/Geometry>
#include <cstddef>
#include <cstdint>
#include <random>
#include <vector>

#include "fusion/core/beam_grid.h"
#include "fusion/core/sensor.h"
#include "fusion/sim/scene.h"

namespace fusion::sim {

struct SimOptions {
  std::uint64_t seed = 1;
  // Reading = q_mu(true range) + N(0, q_sigma(true range)^2) along the ray;
  // false: exact range.
  bool add_noise = true;
  // Probability that a return is dropped (NaN), independently per beam and
  // frame.
  double dropout_probability = 0.0;
  // Rays with no surface within r_max (or a reading beyond r_max) are reported
  // as beyond-range (point = direction * r_max, flag set). Set false for
  // sensors whose r_max is infinite (stereo): they return NaN there.
  bool flag_beyond_range = true;
  // Untextured surfaces give no return (stereo cameras need texture).
  bool require_texture = false;
};

// One frame, row-major in the tessellation's beam order (index = row * cols +
// col).
struct OrganizedCloud {
  int rows = 0;
  int cols = 0;
  std::vector<float> xyz;                  // 3 floats per beam, sensor frame, NaN = no return
  std::vector<std::uint8_t> beyond_range;  // 1 = no return within r_max (direction valid)
  std::vector<float> true_range_m;         // noise-free range of the hit, NaN if none
  [[nodiscard]] std::size_t size() const { return beyond_range.size(); }
};

class RangeSimulator {
 public:
  RangeSimulator(Scene scene, SensorSpec spec, const SimOptions& options = {});
  [[nodiscard]] const SensorSpec& spec() const { return spec_; }
  [[nodiscard]] const BeamTessellation& tessellation() const { return tessellation_; }
  [[nodiscard]] const Scene& scene() const { return scene_; }
  // One frame taken at T_world_sensor (sensor optical frame -> world), of the scene as it is at
  // scene time t_s (Scene::At; a static scene is the same at every time).
  [[nodiscard]] OrganizedCloud Capture(const Eigen::Isometry3d& T_world_sensor, double t_s = 0.0);
  void Reseed(std::uint64_t seed) { rng_.seed(seed); }

 private:
  Scene scene_;
  SensorSpec spec_;
  SimOptions options_;
  BeamTessellation tessellation_;
  std::mt19937_64 rng_;
};

// A copy of a preset with a coarser tessellation (same field of view), e.g. the
// stereo camera's 640 x 480 reduced to 160 x 120 beams for fast tests.
[[nodiscard]] SensorSpec WithTessellation(SensorSpec spec, int cols, int rows);

}  // namespace fusion::sim
