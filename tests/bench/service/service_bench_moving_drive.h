// service_bench (service_bench.cc), scenario 5: the rig's path in front of the board, the two
// sensors simulated along it before the run, and the drive itself: both sensors publishing on
// one clock while small queries run and a sampler notes clouds_in_map for each new version.
#pragma once

#include <grpcpp/grpcpp.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstdint>
#include <filesystem>
#include <map>
#include <mutex>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "fusion/sim/experiment.h"
#include "fusion/sim/scene.h"
#include "fusion/sim/simulator.h"
#include "../../support/waypoint_lap.h"
#include "fusion/v1/map_service.grpc.pb.h"
#include "service_bench_common.h"
#include "service_bench_fusiond.h"
#include "service_bench_queries.h"

namespace fusion::service_bench {

// ---- 5. The service keeps up while moving -------------------------------------------------

// The deployment's configuration (docker/fusiond.pbtxt, beside this file's tests/ folder).
inline const std::string kDeploymentConfig =
    std::filesystem::path(__FILE__).parent_path().parent_path().parent_path().parent_path() /
    "docker" / "fusiond.pbtxt";

// A waypoint of the rig (the SR-3000's optical frame): time, position in the world, yaw to the
// left (no pitch).
// One lap of 10 s from the paper's mounting (the origin, looking along +x): forward 0.85 m
// while yawing to +20 deg, then back while yawing back: 0.17 m/s and 4 deg/s, 1.7 m per lap.
// The board (x = 1.75 m) stays at least 0.9 m ahead. Longer runs repeat the lap.
inline const std::vector<fusion::testing::Waypoint> kLap = {
    {0.0, 0.0, 0.0, 0.0, 0.0}, {5.0, 0.85, 0.0, 0.0, 20.0}, {10.0, 0.0, 0.0, 0.0, 0.0}};

// The SR-3000's pose at t_s: the lap's waypoints, linearly interpolated.
inline Eigen::Isometry3d RigPoseAt(double t_s) { return fusion::testing::PoseOnLap(kLap, t_s); }

// A simulated sensor on the path. Its frames are simulated before the run, each at the pose
// the path gives at its publication time k / rate_hz, so the publisher threads only write: the
// sensors would be other machines, and simulating during the run would take fusiond's CPU.
struct MovingSensor {
  std::string id;
  double rate_hz = 0;
  double r_max_m = 0;
  std::vector<Eigen::Isometry3d> T_world_sensor;  // one per frame
  std::vector<sim::OrganizedCloud> frames;
};

inline MovingSensor SimulateOnPath(const sim::Scene& scene, const sim::SensorRun& run,
                                   const Eigen::Isometry3d& T_rig_sensor, double rate_hz,
                                   double seconds) {
  MovingSensor sensor{run.id, rate_hz, run.spec.r_max_m, {}, {}};
  sim::RangeSimulator simulator(scene, run.spec, run.sim);
  const auto frame_count = static_cast<std::size_t>(seconds * rate_hz);
  for (std::size_t k = 0; k < frame_count; ++k) {
    const Eigen::Isometry3d T_world_sensor =
        RigPoseAt(static_cast<double>(k) / rate_hz) * T_rig_sensor;
    sim::OrganizedCloud frame = simulator.Capture(T_world_sensor);
    std::vector<float>().swap(frame.true_range_m);  // not published: keep the memory down
    sensor.T_world_sensor.push_back(T_world_sensor);
    sensor.frames.push_back(std::move(frame));
  }
  return sensor;
}

// The paper's SR-3000 (176 x 144) at 30 Hz and STOC (160 x 120) at 15 Hz with the paper's
// simulation options, the STOC riding at its paper offset from the SR-3000 (25 mm left, 80 mm
// down, same orientation); simulated on two threads.
inline std::vector<MovingSensor> SimulateMovingSensors(double seconds) {
  const std::vector<sim::SensorRun> runs = sim::PaperSensorRuns();
  const auto run_of = [&runs](const std::string& id) {
    return *std::find_if(runs.begin(), runs.end(),
                         [&id](const sim::SensorRun& run) { return run.id == id; });
  };
  const sim::SensorRun sr = run_of("sr3000");
  const sim::SensorRun stoc = run_of("stoc");
  const Eigen::Isometry3d T_sr_stoc = sr.T_world_sensor.inverse() * stoc.T_world_sensor;
  const sim::Scene scene = sim::PaperBoardScene();
  std::vector<MovingSensor> sensors(2);
  std::thread stoc_thread(
      [&] { sensors[1] = SimulateOnPath(scene, stoc, T_sr_stoc, 15.0, seconds); });
  sensors[0] = SimulateOnPath(scene, sr, Eigen::Isometry3d::Identity(), 30.0, seconds);
  stoc_thread.join();
  return sensors;
}

// When a cloud was written, and its number among the clouds both sensors wrote.
struct WrittenCloud {
  Clock::time_point write_time;
  std::uint64_t clouds_written = 0;  // including this one
};

// Publishes frame k with its pose at start + k / rate_hz. Just before each write it notes the
// time and takes the next number of *clouds_written (shared by both sensors) into *log.
inline StreamStats PublishOnPath(dds_entity_t writer, const MovingSensor& sensor,
                                 Clock::time_point start,
                                 std::atomic<std::uint64_t>* clouds_written,
                                 std::vector<WrittenCloud>* log) {
  StreamStats stats;
  const std::chrono::duration<double> period(1.0 / sensor.rate_hz);
  for (std::size_t k = 0; k < sensor.frames.size(); ++k) {
    const auto due =
        start + std::chrono::duration_cast<Clock::duration>(period * static_cast<double>(k));
    std::this_thread::sleep_until(due);
    const auto write_time = Clock::now();
    if (write_time - due > period) ++stats.late_ticks;
    log->push_back({write_time, ++*clouds_written});
    if (Publisher::Write(writer, sensor.id, k + 1, sensor.T_world_sensor[k], sensor.frames[k]))
      ++stats.written;
    else
      ++stats.write_failures;
    stats.max_write_ms = std::max(stats.max_write_ms, Ms(Clock::now() - write_time));
  }
  return stats;
}

// clouds_in_map of a map version, from one GetStats after the stream announced a version.
struct VersionSample {
  std::uint64_t map_version = 0;
  std::uint64_t clouds_in_map = 0;
};

// Calls GetStats once for each version StreamUpdates announces, on a thread of its own; a
// GetStats that already sees a newer version stands for that one (and the ones between go
// unsampled).
class CloudsInMapSampler {
 public:
  CloudsInMapSampler(Client& client, VersionWatcher& watcher)
      : client_(client), watcher_(watcher), thread_([this] { Run(); }) {}
  ~CloudsInMapSampler() { (void)Stop(); }
  CloudsInMapSampler(const CloudsInMapSampler&) = delete;
  CloudsInMapSampler& operator=(const CloudsInMapSampler&) = delete;

  // Waits up to `timeout` for a sample that counts `clouds` clouds.
  bool WaitForClouds(std::uint64_t clouds, std::chrono::milliseconds timeout) {
    std::unique_lock<std::mutex> lock(mutex_);
    return sampled_.wait_for(lock, timeout, [&] {
      return !samples_.empty() && samples_.back().clouds_in_map >= clouds;
    });
  }
  // Stops sampling; the samples in version order.
  std::vector<VersionSample> Stop() {
    stop_ = true;
    if (thread_.joinable()) thread_.join();
    std::lock_guard<std::mutex> lock(mutex_);
    return samples_;
  }

 private:
  void Run() {
    std::uint64_t last_version = 0;
    while (!stop_) {
      const auto arrival = watcher_.FirstAfter(last_version, 100ms);
      if (!arrival) continue;
      last_version = arrival->first;
      v1::Stats stats;
      if (!client_.Stats(&stats)) continue;
      last_version = std::max(last_version, stats.map_version());
      std::lock_guard<std::mutex> lock(mutex_);
      samples_.push_back({stats.map_version(), stats.clouds_in_map()});
      sampled_.notify_all();
    }
  }

  Client& client_;
  VersionWatcher& watcher_;
  std::atomic<bool> stop_{false};
  std::mutex mutex_;
  std::condition_variable sampled_;
  std::vector<VersionSample> samples_;
  std::thread thread_;  // last: starts once the members above exist
};

// Polls GetStats until clouds_in_map reaches clouds_received (and clouds_received reaches the
// clouds written, or a second has passed for the last ones in flight); returns the wait in ms,
// or -1 when `timeout` passed first. *stats: the last answer.
inline double WaitUntilAllCloudsInMap(Client& client, std::uint64_t clouds_written,
                                      std::chrono::milliseconds timeout, v1::Stats* stats) {
  const auto start = Clock::now();
  while (true) {
    if (client.Stats(stats)) {
      const bool none_in_flight =
          stats->clouds_received() >= clouds_written || Clock::now() - start > 1s;
      if (none_in_flight && stats->clouds_in_map() >= stats->clouds_received())
        return Ms(Clock::now() - start);
    }
    if (Clock::now() - start >= timeout) return -1;
    std::this_thread::sleep_for(50ms);
  }
}

// Everything measured while the sensors drive, and right after.
struct DriveResult {
  std::map<std::string, StreamStats> published;
  std::map<std::string, std::vector<WrittenCloud>> written;  // per sensor, in write order
  std::uint64_t clouds_written = 0;
  std::vector<VersionSample> samples;
  std::vector<std::pair<std::uint64_t, Clock::time_point>> arrivals;
  std::vector<std::string> query_names;
  std::vector<std::vector<double>> query_latency_ms;
  int query_errors = 0, ray_hits = 0;
  double all_in_map_after_ms = -1;  // after the last publish; -1: not within 10 s
  v1::Stats stats;                  // then
  std::map<std::string, v1::SensorCounters> before, after;
};

// Both sensors publish their frames on one clock while small queries run every 2 ms on a
// thread of their own and a sampler notes clouds_in_map for each version the stream
// announces; then waits up to 10 s for every cloud to reach the map.
inline DriveResult Drive(Client& client, const std::vector<MovingSensor>& sensors,
                         const std::vector<dds_entity_t>& writers) {
  DriveResult result;
  client.Counters(&result.before);
  VersionWatcher watcher(client.stub(), 0);
  CloudsInMapSampler sampler(client, watcher);
  const std::vector<SmallQuery> queries = {OnePointQuery(client.stub()),
                                           CastRayQuery(client.stub(), &result.ray_hits)};
  std::atomic<bool> publishing{true};
  std::thread query_thread([&] {
    result.query_latency_ms = RunSmallQueries(
        queries, [&] { return publishing.load(); }, &result.query_errors);
  });
  std::atomic<std::uint64_t> clouds_written{0};
  std::vector<StreamStats> stats(sensors.size());
  std::vector<std::vector<WrittenCloud>> logs(sensors.size());
  std::vector<std::thread> publishers;
  const auto start = Clock::now() + 100ms;  // one clock for both sensors' paths
  for (std::size_t s = 0; s < sensors.size(); ++s) {
    logs[s].reserve(sensors[s].frames.size());
    publishers.emplace_back([&, s] {
      stats[s] = PublishOnPath(writers[s], sensors[s], start, &clouds_written, &logs[s]);
    });
  }
  for (auto& publisher : publishers) publisher.join();
  publishing = false;
  query_thread.join();
  result.clouds_written = clouds_written;
  result.all_in_map_after_ms =
      WaitUntilAllCloudsInMap(client, result.clouds_written, 10000ms, &result.stats);
  (void)sampler.WaitForClouds(result.stats.clouds_in_map(), 2000ms);  // the last version
  result.samples = sampler.Stop();
  // The last GetStats may have seen a version the stream has not announced yet.
  if (!result.samples.empty() && result.samples.back().map_version > 0)
    (void)watcher.FirstAfter(result.samples.back().map_version - 1, 2000ms);
  result.arrivals = watcher.Arrivals();
  client.Counters(&result.after);
  for (std::size_t s = 0; s < sensors.size(); ++s) {
    result.published[sensors[s].id] = stats[s];
    result.written[sensors[s].id] = std::move(logs[s]);
  }
  result.query_names = NamesOf(queries);
  return result;
}

}  // namespace fusion::service_bench
