// service_bench (service_bench.cc): the fusiond child process, its gRPC client, the
// StreamUpdates watcher that times new map versions, and the best-effort DDS writers that
// publish the simulated clouds.
#pragma once

#include <grpcpp/grpcpp.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <csignal>
#include <cstdint>
#include <cstdio>
#include <fstream>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "../../support/subprocess.h"
#include "fusion/dds/participant.h"
#include "fusion/sim/simulator.h"
#include "fusion/v1/map_service.grpc.pb.h"
#include "fusion_dds.h"
#include "service_bench_common.h"

namespace fusion::service_bench {

// One sensor's simulated frames, published round robin.
struct SensorStream {
  std::string id;
  Eigen::Isometry3d pose;
  std::vector<sim::OrganizedCloud> frames;
};

// Best-effort writers (the sensor-data profile fusiond's reader uses), one per sensor.
class Publisher {
 public:
  explicit Publisher(unsigned domain) {
    participant_ = fusion::dds::CreateParticipant(domain, &error_);
    if (participant_ < 0) return;
    topic_ = dds_create_topic(participant_, &fusion_dds_PointCloud_desc, "fusion/points", nullptr,
                              nullptr);
    if (topic_ < 0) error_ = std::string("dds_create_topic: ") + dds_strretcode(topic_);
  }
  ~Publisher() {
    if (participant_ > 0) dds_delete(participant_);
  }
  Publisher(const Publisher&) = delete;
  Publisher& operator=(const Publisher&) = delete;
  [[nodiscard]] const std::string& error() const { return error_; }
  [[nodiscard]] bool ok() const { return participant_ > 0 && topic_ > 0; }

  dds_entity_t CreateWriter() {
    dds_qos_t* qos = dds_create_qos();
    dds_qset_reliability(qos, DDS_RELIABILITY_BEST_EFFORT, 0);
    dds_qset_history(qos, DDS_HISTORY_KEEP_LAST, 1);
    dds_qset_durability(qos, DDS_DURABILITY_VOLATILE);
    const dds_entity_t writer = dds_create_writer(participant_, topic_, qos, nullptr);
    dds_delete_qos(qos);
    return writer;
  }

  static bool WaitForReader(dds_entity_t writer, std::chrono::milliseconds timeout) {
    const auto end = Clock::now() + timeout;
    dds_publication_matched_status_t matched{};
    while (Clock::now() < end) {
      if (dds_get_publication_matched_status(writer, &matched) == DDS_RETCODE_OK &&
          matched.current_count > 0) {
        return true;
      }
      std::this_thread::sleep_for(10ms);
    }
    return false;
  }

  static bool Write(dds_entity_t writer, const std::string& id, std::uint64_t seq,
                    const Eigen::Isometry3d& T, const sim::OrganizedCloud& frame) {
    const Eigen::Quaterniond q(T.rotation());
    fusion_dds_PointCloud sample{};
    sample.sensor_id = const_cast<char*>(id.c_str());
    sample.sequence_number = seq;
    sample.T_world_sensor = {
        T.translation().x(), T.translation().y(), T.translation().z(), q.x(), q.y(), q.z(), q.w()};
    sample.width = static_cast<std::uint32_t>(frame.cols);
    sample.height = static_cast<std::uint32_t>(frame.rows);
    sample.xyz._buffer = const_cast<float*>(frame.xyz.data());
    sample.xyz._length = sample.xyz._maximum = static_cast<std::uint32_t>(frame.xyz.size());
    sample.beyond_range._buffer = const_cast<std::uint8_t*>(frame.beyond_range.data());
    sample.beyond_range._length = sample.beyond_range._maximum =
        static_cast<std::uint32_t>(frame.beyond_range.size());
    return dds_write(writer, &sample) == DDS_RETCODE_OK;
  }

 private:
  dds_entity_t participant_ = 0;
  dds_entity_t topic_ = 0;
  std::string error_;
};

// Publishes a sensor's frames at a fixed rate until `stop`; counts what it wrote.
struct StreamStats {
  std::uint64_t written = 0;
  std::uint64_t write_failures = 0;
  std::uint64_t late_ticks = 0;  // ticks that started more than one period late
  double max_write_ms = 0;
};

inline StreamStats Stream(dds_entity_t writer, const SensorStream& s, double hz, std::uint64_t* seq,
                          const std::atomic<bool>& stop) {
  StreamStats stats;
  const auto period =
      std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(1.0 / hz));
  auto next = Clock::now();
  for (std::size_t i = 0; !stop; ++i) {
    const auto t0 = Clock::now();
    if (t0 - next > period) ++stats.late_ticks;
    if (Publisher::Write(writer, s.id, ++*seq, s.pose, s.frames[i % s.frames.size()])) {
      ++stats.written;
    } else {
      ++stats.write_failures;
    }
    stats.max_write_ms = std::max(stats.max_write_ms, Ms(Clock::now() - t0));
    next += period;
    std::this_thread::sleep_until(next);
  }
  return stats;
}

// Follows StreamUpdates and notes when each map version arrived complete: the moment a planner
// that subscribes learns of it, without the load of polling.
class VersionWatcher {
 public:
  VersionWatcher(v1::FusionMap::Stub& stub, std::uint64_t since) {
    v1::StreamUpdatesRequest request;
    request.set_since_version(since);
    request.set_versions_only(true);
    reader_ = stub.StreamUpdates(&context_, request);
    thread_ = std::thread([this] {
      v1::MapUpdate update;
      while (reader_->Read(&update)) {
        if (!update.complete()) continue;
        const auto now = Clock::now();
        std::lock_guard<std::mutex> lock(mutex_);
        arrivals_.emplace_back(update.map_version(), now);
        changed_.notify_all();
      }
    });
  }
  ~VersionWatcher() {
    context_.TryCancel();
    thread_.join();
    (void)reader_->Finish();
  }
  // Arrival time of the first version newer than `after`, waiting up to `timeout`.
  std::optional<std::pair<std::uint64_t, Clock::time_point>> FirstAfter(
      std::uint64_t after, std::chrono::milliseconds timeout) {
    std::unique_lock<std::mutex> lock(mutex_);
    std::optional<std::pair<std::uint64_t, Clock::time_point>> found;
    changed_.wait_for(lock, timeout, [&] {
      for (const auto& a : arrivals_) {
        if (a.first > after) {
          found = a;
          return true;
        }
      }
      return false;
    });
    return found;
  }
  // Every complete version seen so far with its arrival time, in arrival (= version) order.
  std::vector<std::pair<std::uint64_t, Clock::time_point>> Arrivals() {
    std::lock_guard<std::mutex> lock(mutex_);
    return arrivals_;
  }

 private:
  grpc::ClientContext context_;
  std::unique_ptr<grpc::ClientReader<v1::MapUpdate>> reader_;
  std::mutex mutex_;
  std::condition_variable changed_;
  std::vector<std::pair<std::uint64_t, Clock::time_point>> arrivals_;
  std::thread thread_;
};

class Client {
 public:
  explicit Client(const std::string& address)
      : channel_(grpc::CreateChannel(address, grpc::InsecureChannelCredentials())),
        stub_(v1::FusionMap::NewStub(channel_)) {}
  v1::FusionMap::Stub& stub() { return *stub_; }

  bool Counters(std::map<std::string, v1::SensorCounters>* out) {
    grpc::ClientContext context;
    context.set_deadline(In(5000ms));
    v1::ListSensorsResponse reply;
    if (!stub_->ListSensors(&context, v1::ListSensorsRequest(), &reply).ok()) return false;
    out->clear();
    for (const auto& s : reply.sensors()) (*out)[s.id()] = s.counters();
    return true;
  }
  std::uint64_t Reset() {
    grpc::ClientContext context;
    context.set_deadline(In(5000ms));
    v1::ResetMapResponse reply;
    const auto status = stub_->ResetMap(&context, v1::ResetMapRequest(), &reply);
    return status.ok() ? reply.map_version() : 0;
  }
  bool Stats(v1::Stats* stats) {
    grpc::ClientContext context;
    context.set_deadline(In(5000ms));
    return stub_->GetStats(&context, v1::GetStatsRequest(), stats).ok();
  }

 private:
  std::shared_ptr<grpc::Channel> channel_;
  std::unique_ptr<v1::FusionMap::Stub> stub_;
};

// fusiond as a child process. It logs on stderr: a shell joins that to stdout, which
// Subprocess reads; once it serves, a thread keeps draining the pipe so verbose levels cannot
// block it, and keeps the text for the end.
class FusiondProcess {
 public:
  explicit FusiondProcess(std::vector<std::string> flags)
      : flags_(std::move(flags)), process_(ShellArgv(flags_)) {}
  ~FusiondProcess() { StopDraining(); }
  FusiondProcess(const FusiondProcess&) = delete;
  FusiondProcess& operator=(const FusiondProcess&) = delete;

  // Waits until it serves, then prints its command line; false if it did not start.
  bool Start() {
    const auto port = process_.WaitForOutput(R"(listening on 127\.0\.0\.1:(\d+))", 20s);
    if (!port) {
      std::fprintf(stderr, "fusiond did not start: %s\n", process_.output().c_str());
      return false;
    }
    port_ = *port;
    std::string command = kFusiond;
    for (const auto& flag : flags_) command += " " + flag;
    std::printf("fusiond: %s (port %s)\n\n", command.c_str(), port_.c_str());
    drain_ = std::thread([this] {
      while (!drain_stop_) (void)process_.WaitForOutput("(?!)", 100ms);
    });
    return true;
  }
  [[nodiscard]] std::string address() const { return "127.0.0.1:" + port_; }
  [[nodiscard]] pid_t pid() const { return process_.pid(); }

  // SIGTERM and wait; writes the output to log_path at log levels other than warn, else
  // prints any warnings. Returns the exit code.
  int Stop(const std::string& log_level, const std::string& log_path) {
    StopDraining();
    const int code = process_.Stop(SIGTERM, 10s);
    (void)process_.WaitForOutput("(?!)", 500ms);
    if (log_level != "warn") {
      std::ofstream(log_path) << process_.output();
      std::printf("fusiond output (log level %s) written to %s\n", log_level.c_str(),
                  log_path.c_str());
    } else if (process_.output().find("[warn") != std::string::npos ||
               process_.output().find("[error") != std::string::npos) {
      std::printf("fusiond warnings:\n%s\n", process_.output().c_str());
    }
    return code;
  }

 private:
  static std::vector<std::string> ShellArgv(const std::vector<std::string>& flags) {
    std::vector<std::string> argv = {"/bin/sh", "-c", "exec \"$0\" \"$@\" 2>&1", kFusiond};
    argv.insert(argv.end(), flags.begin(), flags.end());
    return argv;
  }
  void StopDraining() {
    drain_stop_ = true;
    if (drain_.joinable()) drain_.join();
  }

  std::vector<std::string> flags_;
  fusion::testing::Subprocess process_;
  std::string port_;
  std::atomic<bool> drain_stop_{false};
  std::thread drain_;
};

}  // namespace fusion::service_bench
