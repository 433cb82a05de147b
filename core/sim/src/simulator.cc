#include "fusion/sim/simulator.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <utility>

namespace fusion::sim {

RangeSimulator::RangeSimulator(Scene scene, SensorSpec spec, const SimOptions& options)
    : scene_(std::move(scene)),
      spec_(std::move(spec)),
      options_(options),
      tessellation_(spec_),
      rng_(options.seed) {}

OrganizedCloud RangeSimulator::Capture(const Eigen::Isometry3d& T_world_sensor, double t_s) {
  const std::optional<Scene> now =
      scene_.IsDynamic() ? std::optional<Scene>(scene_.At(t_s)) : std::nullopt;
  const Scene& scene = now ? *now : scene_;
  OrganizedCloud cloud;
  cloud.rows = tessellation_.rows();
  cloud.cols = tessellation_.cols();
  const std::size_t n = tessellation_.beam_count();
  const float nan = std::numeric_limits<float>::quiet_NaN();
  cloud.xyz.assign(3 * n, nan);
  cloud.beyond_range.assign(n, 0);
  cloud.true_range_m.assign(n, nan);
  std::normal_distribution<double> normal(0.0, 1.0);
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  const Eigen::Matrix3d R = T_world_sensor.linear();
  const Eigen::Vector3d origin = T_world_sensor.translation();
  for (std::size_t b = 0; b < n; ++b) {
    const Eigen::Vector3d dir = tessellation_.Direction(b);
    // Draw every random number unconditionally so a frame's noise does not
    // depend on which beams hit (reproducible across scene edits).
    const double noise = normal(rng_);
    const double drop = uniform(rng_);
    if (drop < options_.dropout_probability) continue;
    const auto hit = scene.Raycast(origin, R * dir, spec_.r_max_m);
    auto set_beyond = [&] {
      if (!options_.flag_beyond_range) return;
      cloud.beyond_range[b] = 1;
      for (int a = 0; a < 3; ++a) cloud.xyz[3 * b + a] = static_cast<float>(dir[a] * spec_.r_max_m);
    };
    if (!hit) {
      set_beyond();
      continue;
    }
    cloud.true_range_m[b] = static_cast<float>(hit->range_m);
    if (options_.require_texture && !hit->textured) continue;
    if (hit->range_m < spec_.r_min_m) continue;  // too close: the sensor returns nothing
    double reading = hit->range_m;
    if (options_.add_noise) {
      const double sigma = std::max(0.0, spec_.q_sigma(hit->range_m));
      reading = spec_.q_mu(hit->range_m) + sigma * noise;
    }
    if (reading > spec_.r_max_m) {
      set_beyond();
      continue;
    }
    if (reading <= 0.0) continue;
    for (int a = 0; a < 3; ++a) cloud.xyz[3 * b + a] = static_cast<float>(dir[a] * reading);
  }
  return cloud;
}

SensorSpec WithTessellation(SensorSpec spec, int cols, int rows) {
  spec.cols = cols;
  spec.rows = rows;
  return spec;
}

}  // namespace fusion::sim
