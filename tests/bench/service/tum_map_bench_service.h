// tum_map_bench (tum_map_bench.cc), way 1: ours through the service. A fusiond process
// (127.0.0.1:0, private DDS domain) fed by fusion-replay --fast --reliable, timed until
// GetStats clouds_in_map holds every cloud, with its counters and problems reported.
#pragma once

#include <google/protobuf/descriptor.h>
#include <grpcpp/grpcpp.h>
#include <signal.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <fstream>
#include <memory>
#include <optional>
#include <sstream>
#include <string>
#include <thread>

#include "../../support/subprocess.h"
#include "fusion/v1/map_service.grpc.pb.h"
#include "tum_map_bench_common.h"

namespace fusion::tum_map_bench {

// ---- 1. ours through the service -----------------------------------------------------------

class Fusiond {
 public:
  Fusiond(const std::string& config_path, unsigned domain, const std::string& log_level)
      : process_(WithStderr({kBinaryDir + "/service/fusiond", "--config", config_path, "--listen",
                             "127.0.0.1:0", "--dds-domain", std::to_string(domain), "--log-level",
                             log_level})) {
    const auto port = process_.WaitForOutput(R"(listening on 127\.0\.0\.1:(\d+))", 20s);
    if (!port) return;
    address_ = "127.0.0.1:" + *port;
    stub_ =
        v1::FusionMap::NewStub(grpc::CreateChannel(address_, grpc::InsecureChannelCredentials()));
    // Keep draining its output so verbose log levels cannot block it.
    drain_ = std::thread([this] {
      while (!stop_drain_) (void)process_.WaitForOutput("(?!)", 100ms);
    });
  }
  ~Fusiond() { StopDrain(); }
  Fusiond(const Fusiond&) = delete;
  Fusiond& operator=(const Fusiond&) = delete;

  [[nodiscard]] bool ok() const { return stub_ != nullptr; }
  [[nodiscard]] const std::string& address() const { return address_; }
  [[nodiscard]] double CpuSeconds() const { return ProcessCpuSeconds(process_.pid()); }
  // Before ok(): what it printed; after Stop(): everything it printed.
  [[nodiscard]] const std::string& output() const { return process_.output(); }

  std::optional<v1::Stats> Stats() {
    grpc::ClientContext context;
    context.set_deadline(std::chrono::system_clock::now() + 5s);
    v1::Stats stats;
    if (!stub_->GetStats(&context, v1::GetStatsRequest(), &stats).ok()) return std::nullopt;
    return stats;
  }
  std::optional<v1::SensorInfo> Sensor(const std::string& id) {
    grpc::ClientContext context;
    context.set_deadline(std::chrono::system_clock::now() + 5s);
    v1::ListSensorsResponse reply;
    if (!stub_->ListSensors(&context, v1::ListSensorsRequest(), &reply).ok()) return std::nullopt;
    for (const auto& s : reply.sensors()) {
      if (s.id() == id) return s;
    }
    return std::nullopt;
  }
  int Stop() {
    StopDrain();
    const int code = process_.Stop(SIGTERM, 20000ms);
    (void)process_.WaitForOutput("(?!)", 500ms);
    return code;
  }

 private:
  void StopDrain() {
    stop_drain_ = true;
    if (drain_.joinable()) drain_.join();
  }

  Subprocess process_;
  std::string address_;
  std::unique_ptr<v1::FusionMap::Stub> stub_;
  std::atomic<bool> stop_drain_{false};
  std::thread drain_;
};

// Done when every cloud is in the map, or when everything that arrived has been decided
// (integrated, rejected or dropped) and the map holds all integrated clouds.
inline bool ServiceSettled(const v1::Stats& s, std::uint64_t clouds) {
  if (s.clouds_in_map() >= clouds) return true;
  const std::uint64_t decided = s.clouds_integrated() + s.clouds_rejected() + s.clouds_dropped();
  return decided >= clouds && s.clouds_in_map() == s.clouds_integrated();
}

struct ServiceTimes {
  double to_map_s = NAN;        // replay process start -> clouds_in_map == clouds
  double from_publish_s = NAN;  // replay's "publishing" line -> clouds_in_map == clouds
  double replay_exit_s = NAN;   // replay process start -> its exit
  double fusiond_cpu_s = NAN;   // fusiond's CPU time from the replay's start to the map
  int replay_exit_code = -1;
  std::string replay_output;
  v1::Stats stats;
};

// Polls GetStats every 20 ms until the map settles or the timeout passes.
inline std::optional<v1::Stats> WaitForMap(Fusiond& fusiond, std::uint64_t clouds,
                                           double timeout_s) {
  const auto t0 = Clock::now();
  while (SecondsSince(t0) < timeout_s) {
    const auto stats = fusiond.Stats();
    if (stats && ServiceSettled(*stats, clouds)) return stats;
    std::this_thread::sleep_for(20ms);
  }
  return std::nullopt;
}

inline ServiceTimes ReplayIntoService(Fusiond& fusiond, const std::string& recording,
                                      unsigned domain, std::uint64_t clouds, double timeout_s) {
  ServiceTimes times;
  const double cpu0_s = fusiond.CpuSeconds();
  const auto t0 = Clock::now();
  Subprocess replay(WithStderr({kBinaryDir + "/clients/fusion-replay", recording, "--domain",
                                std::to_string(domain), "--fast", "--reliable", "--wait-readers",
                                "1", "--quiet"}));
  const bool publishing = replay.WaitForOutput(R"(publishing \d+ clouds)", 30s).has_value();
  const double publish_s = SecondsSince(t0);
  const auto stats = publishing ? WaitForMap(fusiond, clouds, timeout_s) : std::nullopt;
  const double map_s = SecondsSince(t0);
  times.fusiond_cpu_s = fusiond.CpuSeconds() - cpu0_s;
  if (stats) {
    times.stats = *stats;
    times.to_map_s = map_s;
    times.from_publish_s = map_s - publish_s;
  }
  (void)replay.WaitForOutput(R"(published \d+ clouds|not every reader)", 60s);
  times.replay_exit_code = replay.Wait(40000ms);
  times.replay_exit_s = SecondsSince(t0);
  times.replay_output = replay.output();
  return times;
}

// A SensorCounters field by name (0 if this build's message has no such field, e.g. merged).
inline std::optional<std::uint64_t> CounterField(const v1::SensorCounters& c,
                                                 const std::string& name) {
  const auto* field = c.GetDescriptor()->FindFieldByName(name);
  if (field == nullptr || field->cpp_type() != google::protobuf::FieldDescriptor::CPPTYPE_UINT64 ||
      field->is_repeated()) {
    return std::nullopt;
  }
  return c.GetReflection()->GetUInt64(c, field);
}

inline void PrintServiceCounters(const v1::SensorInfo& sensor, const v1::Stats& stats) {
  const auto& c = sensor.counters();
  const auto merged = CounterField(c, "merged");
  std::printf(
      "service counters (ListSensors '%s', %u x %u beams, sensor memory %.1f MB): received %llu, "
      "rejected %llu, dropped %llu, integrated %llu, merged %s, points_updated %llu, "
      "points_beyond_range %llu, points_missing %llu, points_rejected %llu, changes_detected "
      "%llu\n",
      sensor.id().c_str(), sensor.cols(), sensor.rows(), Megabytes(sensor.memory_bytes()),
      (unsigned long long)c.received(), (unsigned long long)c.rejected(),
      (unsigned long long)c.dropped(), (unsigned long long)c.integrated(),
      merged ? std::to_string(*merged).c_str() : "(no such counter)",
      (unsigned long long)c.points_updated(), (unsigned long long)c.points_beyond_range(),
      (unsigned long long)c.points_missing(), (unsigned long long)c.points_rejected(),
      (unsigned long long)c.changes_detected());
  for (const auto& [reason, n] : c.rejected_by_reason())
    std::printf("  rejected because %s: %llu\n", reason.c_str(), (unsigned long long)n);
  std::printf(
      "service stats (GetStats): clouds received %llu, rejected %llu, dropped %llu, integrated "
      "%llu, in map %llu, renders %llu, map version %llu, map_leaves %llu, map_memory_bytes "
      "%llu, sensor_memory_bytes %llu\n",
      (unsigned long long)stats.clouds_received(), (unsigned long long)stats.clouds_rejected(),
      (unsigned long long)stats.clouds_dropped(), (unsigned long long)stats.clouds_integrated(),
      (unsigned long long)stats.clouds_in_map(), (unsigned long long)stats.renders(),
      (unsigned long long)stats.map_version(), (unsigned long long)stats.map_leaves(),
      (unsigned long long)stats.map_memory_bytes(),
      (unsigned long long)stats.sensor_memory_bytes());
  for (const auto& [reason, n] : stats.rejected_by_reason())
    std::printf("  (all sensors) rejected because %s: %llu\n", reason.c_str(),
                (unsigned long long)n);
}

// fusiond's warning and error lines.
inline void PrintFusiondProblems(const std::string& output) {
  std::istringstream lines(output);
  std::string line;
  int problems = 0;
  while (std::getline(lines, line)) {
    if (line.find("warn") == std::string::npos && line.find("error") == std::string::npos &&
        line.find("critical") == std::string::npos) {
      continue;
    }
    if (problems++ < 40) std::printf("  fusiond: %s\n", line.c_str());
  }
  std::printf("fusiond warning/error lines: %d%s\n", problems, problems > 40 ? " (first 40)" : "");
}

// At verbose log levels the whole log goes to a file that outlives the temporary folder.
inline void SaveLog(const std::string& output) {
  const std::string path = "/tmp/tum_map_bench_fusiond.log";
  std::ofstream(path) << output;
  std::printf("fusiond output written to %s\n", path.c_str());
}

inline std::optional<Row> RunService(const std::string& config_path, const std::string& recording,
                                     std::uint64_t clouds, const Options& options) {
  const unsigned domain = fusion::testing::PrivateDomainId();
  Fusiond fusiond(config_path, domain, options.log_level);
  if (!fusiond.ok()) {
    std::fprintf(stderr, "fusiond did not start: %s\n", fusiond.output().c_str());
    return std::nullopt;
  }
  std::printf(
      "fusiond: %s/service/fusiond --config %s --listen 127.0.0.1:0 --dds-domain %u "
      "--log-level %s (%s)\n",
      kBinaryDir.c_str(), config_path.c_str(), domain, options.log_level.c_str(),
      fusiond.address().c_str());
  const ServiceTimes times =
      ReplayIntoService(fusiond, recording, domain, clouds, options.timeout_s);
  const auto sensor = fusiond.Sensor(kSensorId);
  std::printf("fusion-replay: exit %d after %.2f s: %s", times.replay_exit_code,
              times.replay_exit_s, times.replay_output.c_str());
  if (std::isnan(times.to_map_s)) {
    std::printf("service: the map did not settle within %.0f s\n", options.timeout_s);
  } else {
    std::printf(
        "service: clouds_in_map %llu of %llu after %.2f s from the replay's start "
        "(%.2f s after its 'publishing' line, i.e. without DDS discovery); fusiond CPU "
        "time meanwhile %.2f s (its integrator and renderer threads run at nice 10)\n",
        (unsigned long long)times.stats.clouds_in_map(), (unsigned long long)clouds, times.to_map_s,
        times.from_publish_s, times.fusiond_cpu_s);
  }
  if (sensor) PrintServiceCounters(*sensor, times.stats);
  std::printf("fusiond exit code %d\n", fusiond.Stop());
  PrintFusiondProblems(fusiond.output());
  if (options.log_level != "warn") SaveLog(fusiond.output());
  if (std::isnan(times.to_map_s) || times.stats.clouds_in_map() < clouds) return std::nullopt;
  return Row{"ours, fusiond (replay --fast --reliable over DDS)", times.to_map_s,
             times.stats.map_leaves(), static_cast<double>(times.stats.map_memory_bytes()),
             times.fusiond_cpu_s};
}

}  // namespace fusion::tum_map_bench
