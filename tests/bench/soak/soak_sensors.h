// soak: the two simulated sensors. One lap of frames is simulated before the run (so that the
// publishers only write during it, as if the sensors were other machines) and published in a
// loop at a fixed rate over DDS with the tests' TestPublisher (loopback configuration).
#pragma once

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "../../support/dds_publisher.h"
#include "../../support/waypoint_lap.h"
#include "fusion/sim/experiment.h"
#include "fusion/sim/scene.h"
#include "fusion/sim/simulator.h"

namespace fusion::soak {

using SoakClock = std::chrono::steady_clock;

// A waypoint of the rig (the SR-3000's optical frame): time, position, yaw to the left.
// A closed 20 s lap in front of the board (x = 1.75 m, which stays >= 0.95 m ahead): forward
// while turning left, across to the left, back to the right, home. 0.07-0.16 m/s, <= 5 deg/s.
inline const std::vector<fusion::testing::Waypoint> kLap = {{0, 0.0, 0.0, 0.0, 0},
                                           {5, 0.8, 0.0, 0.0, 15},
                                           {10, 0.6, 0.4, 0.05, -10},
                                           {15, 0.2, -0.3, -0.05, 10},
                                           {20, 0.0, 0.0, 0.0, 0}};
constexpr double kLapS = 20.0;

inline Eigen::Isometry3d RigPoseAt(double t_s) { return fusion::testing::PoseOnLap(kLap, t_s); }

// One frame as TestPublisher writes it: points, flags and the pose.
inline testing::TestCloud ToTestCloud(const std::string& id, sim::OrganizedCloud frame,
                                      const Eigen::Isometry3d& T_world_sensor) {
  testing::TestCloud cloud;
  cloud.sensor_id = id;
  cloud.SetPose(T_world_sensor);
  cloud.width = static_cast<std::uint32_t>(frame.cols);
  cloud.height = static_cast<std::uint32_t>(frame.rows);
  cloud.xyz = std::move(frame.xyz);
  cloud.beyond_range = std::move(frame.beyond_range);
  return cloud;
}

// A sensor's lap: frame k taken at the rig pose of k / rate_hz.
inline std::vector<testing::TestCloud> SimulateLap(const sim::SensorRun& run,
                                                   const Eigen::Isometry3d& T_rig_sensor,
                                                   const std::string& id, double rate_hz) {
  sim::RangeSimulator simulator(sim::PaperBoardScene(), run.spec, run.sim);
  const auto frame_count = static_cast<std::size_t>(std::lround(kLapS * rate_hz));
  std::vector<testing::TestCloud> lap;
  lap.reserve(frame_count);
  for (std::size_t k = 0; k < frame_count; ++k) {
    const Eigen::Isometry3d T = RigPoseAt(static_cast<double>(k) / rate_hz) * T_rig_sensor;
    lap.push_back(ToTestCloud(id, simulator.Capture(T), T));
  }
  return lap;
}

struct SensorLaps {
  std::vector<testing::TestCloud> sr, stoc;
};

// The paper's SR-3000 and STOC (stoc_cols x stoc_rows points, same field of view) with the
// paper's simulation options, the STOC at its paper offset on the rig; on two threads.
inline SensorLaps SimulateLaps(const std::string& sr_id, const std::string& stoc_id, int stoc_cols,
                               int stoc_rows, double rate_hz) {
  sim::PaperRunOptions options;
  options.stereo_cols = stoc_cols;
  options.stereo_rows = stoc_rows;
  const auto runs = sim::PaperSensorRuns(options);
  const auto run_of = [&runs](const std::string& name) {
    return *std::find_if(runs.begin(), runs.end(), [&](const auto& r) { return r.id == name; });
  };
  const sim::SensorRun sr = run_of("sr3000"), stoc = run_of("stoc");
  const Eigen::Isometry3d T_sr_stoc = sr.T_world_sensor.inverse() * stoc.T_world_sensor;
  SensorLaps laps;
  std::thread stoc_thread([&] { laps.stoc = SimulateLap(stoc, T_sr_stoc, stoc_id, rate_hz); });
  laps.sr = SimulateLap(sr, Eigen::Isometry3d::Identity(), sr_id, rate_hz);
  stoc_thread.join();
  return laps;
}

// Publishes a lap in a loop at rate_hz on a thread of its own, from its own DDS participant.
class SensorPublisher {
 public:
  SensorPublisher(unsigned domain, std::vector<testing::TestCloud> lap, double rate_hz)
      : publisher_(domain), lap_(std::move(lap)), rate_hz_(rate_hz) {}
  ~SensorPublisher() { Stop(); }
  SensorPublisher(const SensorPublisher&) = delete;
  SensorPublisher& operator=(const SensorPublisher&) = delete;

  // False (with error()) if the writer failed or no reader matched within 10 s.
  bool Start() {
    if (!publisher_.ok() || !publisher_.WaitForReader(std::chrono::seconds(10))) return false;
    thread_ = std::thread([this] { Run(); });
    return true;
  }
  void Stop() {
    stop_ = true;
    if (thread_.joinable()) thread_.join();
  }
  [[nodiscard]] std::string error() const {
    return publisher_.ok() ? "no DDS reader matched within 10 s" : publisher_.error();
  }
  [[nodiscard]] const std::string& id() const { return lap_.front().sensor_id; }
  [[nodiscard]] std::size_t points_per_frame() const { return lap_.front().xyz.size() / 3; }
  std::atomic<std::uint64_t> written{0}, write_failures{0}, late_ticks{0};

 private:
  void Run() {
    const std::chrono::duration<double> period(1.0 / rate_hz_);
    const auto start = SoakClock::now();
    for (std::uint64_t k = 0; !stop_; ++k) {
      const auto due =
          start + std::chrono::duration_cast<SoakClock::duration>(period * static_cast<double>(k));
      std::this_thread::sleep_until(due);
      if (SoakClock::now() - due > period) ++late_ticks;
      testing::TestCloud& cloud = lap_[k % lap_.size()];
      cloud.sequence_number = k + 1;
      ++(publisher_.Publish(cloud) ? written : write_failures);
    }
  }

  testing::TestPublisher publisher_;
  std::vector<testing::TestCloud> lap_;
  double rate_hz_;
  std::atomic<bool> stop_{false};
  std::thread thread_;
};

}  // namespace fusion::soak
