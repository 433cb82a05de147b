// service_bench (service_bench.cc), scenario 5: the service keeps up while moving. A second
// fusiond with the deployment's configuration, the drive (service_bench_moving_drive.h), then
// its report: counters and completeness, DDS-to-queryable latency per sensor, small-query
// latency meanwhile, and memory next to an OctoMap OcTree built here from the same clouds.
#pragma once

#include <google/protobuf/descriptor.h>
#include <google/protobuf/text_format.h>
#include <octomap/OcTree.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "fusion/sim/experiment.h"
#include "fusion/v1/config.pb.h"
#include "fusion/v1/map_service.grpc.pb.h"
#include "service_bench_common.h"
#include "service_bench_fusiond.h"
#include "service_bench_moving_drive.h"
#include "service_bench_queries.h"

namespace fusion::service_bench {

// DDS-to-queryable latency of one sensor's clouds.
struct QueryableLatencies {
  std::vector<double> latency_ms;
  // Counted by clouds_in_map only after the last announced version: fusiond counts a cloud in
  // the map without a new version when its render changed no voxel, so the stream says nothing.
  std::size_t without_new_version = 0;
  std::size_t never_in_map = 0;
};

// From each logged cloud's write to the arrival on the stream of the first version whose
// clouds_in_map is at least the cloud's number among all clouds written. An approximation:
// clouds_in_map counts the integrated clouds of both sensors, each sensor's in arrival order,
// and the two sensors' clouds are taken to be integrated in the order they were written (they
// are written milliseconds apart); a cloud lost or dropped before integration makes every later
// one look later. Unsampled versions, and clouds counted while the version stayed the same,
// can only lengthen a latency. final_clouds_in_map: GetStats at the end.
inline QueryableLatencies QueryableLatenciesOf(
    const std::vector<WrittenCloud>& log, const std::vector<VersionSample>& samples,
    const std::vector<std::pair<std::uint64_t, Clock::time_point>>& arrivals,
    std::uint64_t final_clouds_in_map) {
  QueryableLatencies result;
  auto sample = samples.begin();
  auto arrival = arrivals.begin();
  for (const WrittenCloud& cloud : log) {  // in write order: clouds_written increases
    while (sample != samples.end() && sample->clouds_in_map < cloud.clouds_written) ++sample;
    if (sample != samples.end()) {
      while (arrival != arrivals.end() && arrival->first < sample->map_version) ++arrival;
    }
    if (sample != samples.end() && arrival != arrivals.end()) {
      result.latency_ms.push_back(Ms(arrival->second - cloud.write_time));
    } else if (cloud.clouds_written <= final_clouds_in_map) {
      ++result.without_new_version;
    } else {
      ++result.never_in_map;
    }
  }
  return result;
}

// ListSensors' `merged` counter (clouds integrated while the renderer was behind), where this
// build's proto has one.
inline std::optional<std::uint64_t> MergedCounter(const v1::SensorCounters& counters) {
  const auto* field = counters.GetDescriptor()->FindFieldByName("merged");
  if (field == nullptr || field->is_repeated() ||
      field->cpp_type() != google::protobuf::FieldDescriptor::CPPTYPE_UINT64) {
    return std::nullopt;
  }
  return counters.GetReflection()->GetUInt64(counters, field);
}

// A "Vm..." line of /proc/<pid>/status in MB (-1 if absent).
inline double ProcStatusMb(pid_t pid, const std::string& field) {
  std::ifstream in("/proc/" + std::to_string(pid) + "/status");
  for (std::string line; std::getline(in, line);) {
    if (line.rfind(field + ":", 0) == 0) return std::atof(line.c_str() + field.size() + 1) / 1024;
  }
  return -1;
}

inline void PrintCountersAndCompleteness(const DriveResult& r,
                                         const std::vector<MovingSensor>& sensors) {
  std::printf("counters (ListSensors):\n\n");
  std::vector<std::pair<std::string, double>> rates;
  for (const auto& sensor : sensors) rates.emplace_back(sensor.id, sensor.rate_hz);
  PrintCounterTable(rates, r.published, r.before, r.after);
  std::string merged;
  for (const auto& sensor : sensors) {
    const auto count = MergedCounter(r.after.at(sensor.id));
    if (count) merged += " " + sensor.id + " " + std::to_string(*count);
  }
  std::printf("\nmerged (integrated while the renderer was behind):%s\n\n",
              merged.empty() ? " not reported by this build's ListSensors" : merged.c_str());
  const v1::Stats& s = r.stats;
  if (r.all_in_map_after_ms >= 0) {
    std::printf(
        "every cloud in the map: yes, clouds_in_map %llu = clouds_received %llu, %.0f ms after "
        "the last publish (%llu written)\n\n",
        static_cast<unsigned long long>(s.clouds_in_map()),
        static_cast<unsigned long long>(s.clouds_received()), r.all_in_map_after_ms,
        static_cast<unsigned long long>(r.clouds_written));
  } else {
    std::printf(
        "every cloud in the map: NO, 10 s after the last publish clouds_in_map %llu < "
        "clouds_received %llu (%llu written, %llu dropped, %llu rejected, %llu integrated)\n\n",
        static_cast<unsigned long long>(s.clouds_in_map()),
        static_cast<unsigned long long>(s.clouds_received()),
        static_cast<unsigned long long>(r.clouds_written),
        static_cast<unsigned long long>(s.clouds_dropped()),
        static_cast<unsigned long long>(s.clouds_rejected()),
        static_cast<unsigned long long>(s.clouds_integrated()));
  }
}

inline void PrintQueryableLatencies(const DriveResult& r,
                                    const std::vector<MovingSensor>& sensors) {
  std::printf(
      "DDS-to-queryable latency: dds_write of a frame to the arrival (StreamUpdates, "
      "versions_only) of the first version whose GetStats clouds_in_map counts it (the n-th "
      "cloud written of both sensors counts once clouds_in_map >= n: an approximation)\n\n"
      "| frames | samples | median ms | p90 ms | p99 ms | max ms | in the map without a new "
      "version | never in the map |\n"
      "|---|---|---|---|---|---|---|---|\n");
  for (const auto& sensor : sensors) {
    const QueryableLatencies q = QueryableLatenciesOf(r.written.at(sensor.id), r.samples,
                                                      r.arrivals, r.stats.clouds_in_map());
    const auto& v = q.latency_ms;
    std::printf("| %s, %.0f Hz | %zu | %.1f | %.1f | %.1f | %.1f | %zu | %zu |\n",
                sensor.id.c_str(), sensor.rate_hz, v.size(), Percentile(v, 0.5), Percentile(v, 0.9),
                Percentile(v, 0.99), v.empty() ? NAN : *std::max_element(v.begin(), v.end()),
                q.without_new_version, q.never_in_map);
  }
  std::printf(
      "\nversions announced on the stream: %zu (last %llu), sampled with GetStats: %zu (last: "
      "version %llu, clouds_in_map %llu); at the end: version %llu, clouds_in_map %llu, "
      "renders %llu\n\n",
      r.arrivals.size(),
      static_cast<unsigned long long>(r.arrivals.empty() ? 0 : r.arrivals.back().first),
      r.samples.size(),
      static_cast<unsigned long long>(r.samples.empty() ? 0 : r.samples.back().map_version),
      static_cast<unsigned long long>(r.samples.empty() ? 0 : r.samples.back().clouds_in_map),
      static_cast<unsigned long long>(r.stats.map_version()),
      static_cast<unsigned long long>(r.stats.clouds_in_map()),
      static_cast<unsigned long long>(r.stats.renders()));
}

inline void PrintSmallQueries(const DriveResult& r) {
  std::printf(
      "small queries meanwhile (one every 2 ms, alternating, while the sensors publish):\n\n"
      "| sensors | query | samples | p50 ms | p99 ms | max ms |\n"
      "|---|---|---|---|---|---|\n");
  PrintQueryRows("sr3000 30 Hz + stoc 15 Hz, moving", r.query_names, r.query_latency_ms);
  std::printf("\nerrors: %d; CastRay hits: %d\n\n", r.query_errors, r.ray_hits);
}

// The OctoMap baseline for the memory comparison: one OcTree built in this process from the
// very clouds published, in publication order, each with its sensor's origin and a max range
// of min(render range, sensor's r_max) as fusion::sim::InsertIntoOctoMap inserts them
// (beyond-range beams clear up to the max range).
inline std::unique_ptr<octomap::OcTree> BuildOctoMapBaseline(
    const std::vector<MovingSensor>& sensors, double resolution_m, double max_range_m) {
  auto tree = std::make_unique<octomap::OcTree>(resolution_m);
  std::vector<std::size_t> next(sensors.size(), 0);
  const auto due_s = [&](std::size_t s) {
    return static_cast<double>(next[s]) / sensors[s].rate_hz;
  };
  while (true) {
    std::optional<std::size_t> first;  // the sensor whose next frame was published first
    for (std::size_t s = 0; s < sensors.size(); ++s) {
      if (next[s] < sensors[s].frames.size() && (!first || due_s(s) < due_s(*first))) first = s;
    }
    if (!first) break;
    const MovingSensor& sensor = sensors[*first];
    const std::size_t k = next[*first]++;
    const double range_m = max_range_m > 0 ? std::min(max_range_m, sensor.r_max_m) : sensor.r_max_m;
    sim::InsertIntoOctoMap(sensor.frames[k], sensor.T_world_sensor[k], range_m, tree.get());
  }
  return tree;
}

// fusiond's map and process memory at the end of the run.
struct FusiondMemory {
  v1::Stats stats;
  double rss_mb = -1, peak_rss_mb = -1;
};

inline FusiondMemory ReadFusiondMemory(Client& client, pid_t pid) {
  FusiondMemory memory;
  (void)client.Stats(&memory.stats);
  memory.rss_mb = ProcStatusMb(pid, "VmRSS");
  memory.peak_rss_mb = ProcStatusMb(pid, "VmHWM");
  return memory;
}

inline void CompareMemory(const FusiondMemory& fusiond, const std::vector<MovingSensor>& sensors,
                          double max_range_m) {
  const double resolution_m = fusiond.stats.resolution_m();
  const auto t0 = Clock::now();
  const auto tree = BuildOctoMapBaseline(sensors, resolution_m, max_range_m);
  const double build_s = std::chrono::duration<double>(Clock::now() - t0).count();
  std::size_t clouds = 0;
  for (const auto& sensor : sensors) clouds += sensor.frames.size();
  const double kMb = 1024.0 * 1024.0;
  std::printf(
      "memory at the end:\n\n"
      "| map | voxel | leaves | map memory MB | notes |\n|---|---|---|---|---|\n");
  std::printf(
      "| fusiond (GetStats map_leaves, map_memory_bytes) | %.0f cm | %llu | %.1f | fusiond RSS "
      "%.1f MB (peak %.1f MB); beam grids (sensor_memory_bytes) %.1f MB |\n",
      resolution_m * 100, static_cast<unsigned long long>(fusiond.stats.map_leaves()),
      static_cast<double>(fusiond.stats.map_memory_bytes()) / kMb, fusiond.rss_mb,
      fusiond.peak_rss_mb, static_cast<double>(fusiond.stats.sensor_memory_bytes()) / kMb);
  std::printf(
      "| OctoMap OcTree in the bench (getNumLeafNodes, memoryUsage) | %.0f cm | %zu | %.1f | "
      "the same %zu clouds, insertPointCloud from each sensor origin, max range %.1f m; "
      "built in %.1f s |\n\n",
      resolution_m * 100, tree->getNumLeafNodes(), static_cast<double>(tree->memoryUsage()) / kMb,
      clouds, max_range_m, build_s);
}

// Scenario 5's configuration file: the deployment's, or a merged copy in `dir` when --max-range
// or --config is given; its map section in *map.
inline bool MovingConfig(const BenchOptions& options, const std::string& dir, std::string* path,
                         v1::MapConfig* map) {
  const std::string deployment_text = ReadFile(kDeploymentConfig);
  if (deployment_text.empty()) {
    std::fprintf(stderr, "cannot read %s\n", kDeploymentConfig.c_str());
    return false;
  }
  const auto text = WithBenchOverrides(deployment_text, options);
  v1::ServiceConfig config;
  if (!text || !google::protobuf::TextFormat::ParseFromString(*text, &config)) {
    std::fprintf(stderr, "bad --config text\n");
    return false;
  }
  *map = config.map();
  *path = kDeploymentConfig;
  if (*text != deployment_text) {
    *path = dir + "/fusiond_moving.pbtxt";
    std::ofstream(*path) << *text;
    std::printf("configuration (%s with --max-range / --config merged):\n\n```\n%s```\n\n",
                kDeploymentConfig.c_str(), text->c_str());
  }
  return true;
}

inline bool CreateWriters(Publisher& publisher, std::size_t count,
                          std::vector<dds_entity_t>* writers) {
  if (!publisher.ok()) {
    std::fprintf(stderr, "publisher: %s\n", publisher.error().c_str());
    return false;
  }
  for (std::size_t i = 0; i < count; ++i) {
    writers->push_back(publisher.CreateWriter());
    if (writers->back() < 0 || !Publisher::WaitForReader(writers->back(), 10s)) {
      std::fprintf(stderr, "no DDS reader matched\n");
      return false;
    }
  }
  return true;
}

inline int RunMovingScenario(const BenchOptions& options, const std::string& dir, unsigned domain) {
  const double seconds = options.seconds_given ? options.seconds : 20.0;
  std::printf(
      "## 5. The service keeps up while moving: sr3000 (176 x 144) at 30 Hz + stoc (160 x 120) "
      "at 15 Hz driving in front of the board, %.0f s, docker/fusiond.pbtxt, small queries "
      "every 2 ms\n\n"
      "path: from the origin looking along +x, forward to x = 0.85 m while yawing to +20 deg in "
      "5 s, back in 5 s, repeated (0.17 m/s, 4 deg/s; the board at x = 1.75 m stays >= 0.9 m "
      "ahead); stoc 25 mm left of and 80 mm below sr3000 on the same rig\n\n",
      seconds);
  const auto simulate_start = Clock::now();
  const std::vector<MovingSensor> sensors = SimulateMovingSensors(seconds);
  std::printf("frames simulated before the run: sr3000 %zu, stoc %zu (%.1f s)\n\n",
              sensors[0].frames.size(), sensors[1].frames.size(),
              std::chrono::duration<double>(Clock::now() - simulate_start).count());
  std::string config;
  v1::MapConfig map_config;
  if (!MovingConfig(options, dir, &config, &map_config)) return 2;
  // --snapshot: the deployment's /var/lib/fusion/map.ot is not this bench's to read or write.
  FusiondProcess fusiond({"--config", config, "--listen", "127.0.0.1:0", "--dds-domain",
                          std::to_string(domain), "--log-level", options.log_level, "--snapshot",
                          dir + "/moving_map.ot"});
  if (!fusiond.Start()) return 1;
  Client client(fusiond.address());
  Publisher publisher(domain);
  std::vector<dds_entity_t> writers;
  if (!CreateWriters(publisher, sensors.size(), &writers)) return 1;

  const DriveResult result = Drive(client, sensors, writers);
  PrintCountersAndCompleteness(result, sensors);
  PrintQueryableLatencies(result, sensors);
  PrintSmallQueries(result);
  const FusiondMemory memory = ReadFusiondMemory(client, fusiond.pid());
  const int code = fusiond.Stop(options.log_level, "/tmp/service_bench_fusiond_moving.log");
  CompareMemory(memory, sensors, map_config.max_range_m());
  std::printf("fusiond (scenario 5) exit code %d\n\n", code);
  return 0;
}

}  // namespace fusion::service_bench
