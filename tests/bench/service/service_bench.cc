// fusiond end-to-end performance (issue 5): a real fusiond process on 127.0.0.1:0 in a private
// DDS domain, fed over DDS with simulated clouds of the paper's board scene by publisher
// threads in this process, queried over gRPC on loopback. Prints one table per scenario:
//   1. DDS-to-queryable latency of one SR-3000 frame (176 x 144) at the default render cadence
//   2. batched QueryPoints throughput
//   3. small-query latency (QueryPoints of 1 and 10 points, CastRay) while sr3000 and stoc
//      stream at 30 Hz each
//   4. samples dropped with sr3000 at 30 Hz and stoc (160 x 120) at 15 Hz
//   5. the service keeps up while moving: a second fusiond with the deployment's
//      docker/fusiond.pbtxt (2 cm voxels, render range 4 m), sr3000 at 30 Hz and stoc at 15 Hz
//      driving back and forth in front of the board (0.17 m/s, 4 deg/s): counters, whether
//      every cloud reaches the map, DDS-to-queryable latency per frame, small-query latency
//      meanwhile, and memory next to an OctoMap OcTree built here from the same clouds
// Usage: service_bench [--seconds S] [--trials N] [--log-level LEVEL] [--max-range M]
//                      [--config TEXT] [--only LIST]
//   --seconds: duration of scenarios 3 and 4 (default 10) and of scenario 5 (default 20);
//   --trials: scenario 1 (default 20); --log-level: fusiond's (default warn; debug logs render
//   times, written to /tmp/service_bench_fusiond.log, scenario 5's fusiond to
//   /tmp/service_bench_fusiond_moving.log); --max-range: map.max_range_m; --config: more
//   fusiond configuration (text format, e.g. "map { render_threads: 1 }"), merged over each
//   scenario's configuration; --only: scenarios to run, e.g. 1,3 (default all; 2 and 3 need
//   the board mapped by 1).
#include <google/protobuf/descriptor.h>
#include <google/protobuf/text_format.h>
#include <grpcpp/grpcpp.h>
#include <octomap/OcTree.h>
#include <stdlib.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <random>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "../../support/subprocess.h"
#include "fusion/dds/participant.h"
#include "fusion/sim/experiment.h"
#include "fusion/sim/scene.h"
#include "fusion/sim/simulator.h"
#include "fusion/v1/config.pb.h"
#include "fusion/v1/map_service.grpc.pb.h"
#include "fusion_dds.h"

namespace {

using Clock = std::chrono::steady_clock;
using namespace std::chrono_literals;
namespace v1 = fusion::v1;
namespace sim = fusion::sim;

const std::string kFusiond = std::string(FUSION_BINARY_DIR) + "/service/fusiond";
const Eigen::Vector3d kOnBoard(1.75, 0.0, 0.2);  // a voxel of the paper's board (x = 1.75)

double Ms(Clock::duration d) { return std::chrono::duration<double, std::milli>(d).count(); }

std::chrono::system_clock::time_point In(std::chrono::milliseconds ms) {
  return std::chrono::system_clock::now() + ms;
}

v1::Point P(const Eigen::Vector3d& v) {
  v1::Point p;
  p.set_x(v.x());
  p.set_y(v.y());
  p.set_z(v.z());
  return p;
}

// Nearest-rank percentile of unsorted values.
double Percentile(std::vector<double> v, double q) {
  if (v.empty()) return NAN;
  std::sort(v.begin(), v.end());
  const auto rank = static_cast<std::size_t>(std::ceil(q * static_cast<double>(v.size())));
  return v[std::min(v.size() - 1, rank == 0 ? 0 : rank - 1)];
}

std::string LoadAverage() {
  std::ifstream in("/proc/loadavg");
  std::string a, b, c;
  in >> a >> b >> c;
  return a + " " + b + " " + c;
}

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

StreamStats Stream(dds_entity_t writer, const SensorStream& s, double hz, std::uint64_t* seq,
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

struct CounterDelta {
  std::uint64_t received = 0, dropped = 0, rejected = 0, integrated = 0;
};

CounterDelta Delta(const v1::SensorCounters& a, const v1::SensorCounters& b) {
  return {b.received() - a.received(), b.dropped() - a.dropped(), b.rejected() - a.rejected(),
          b.integrated() - a.integrated()};
}

void PrintCounterTable(const std::vector<std::pair<std::string, double>>& rates,
                       const std::map<std::string, StreamStats>& published,
                       const std::map<std::string, v1::SensorCounters>& before,
                       const std::map<std::string, v1::SensorCounters>& after) {
  std::printf(
      "| sensor | rate | published | received | DDS lost (published-received) | "
      "dropped (queue) | rejected | integrated | not integrated (published-integrated) "
      "|\n|---|---|---|---|---|---|---|---|---|\n");
  for (const auto& [id, hz] : rates) {
    const auto& pub = published.at(id);
    const CounterDelta d = Delta(before.at(id), after.at(id));
    std::printf(
        "| %s | %.0f Hz | %llu | %llu | %lld | %llu | %llu | %llu | %lld |\n", id.c_str(), hz,
        static_cast<unsigned long long>(pub.written), static_cast<unsigned long long>(d.received),
        static_cast<long long>(pub.written) - static_cast<long long>(d.received),
        static_cast<unsigned long long>(d.dropped), static_cast<unsigned long long>(d.rejected),
        static_cast<unsigned long long>(d.integrated),
        static_cast<long long>(pub.written) - static_cast<long long>(d.integrated));
    if (pub.write_failures > 0 || pub.late_ticks > 0) {
      std::printf(
          "|   (%s publisher: %llu dds_write failures, %llu late ticks, max write %.1f "
          "ms) |||||||||\n",
          id.c_str(), static_cast<unsigned long long>(pub.write_failures),
          static_cast<unsigned long long>(pub.late_ticks), pub.max_write_ms);
    }
  }
}

// A kind of small query for the latency loops: its name and one call.
struct SmallQuery {
  std::string name;
  std::function<grpc::Status(grpc::ClientContext*)> call;
};

SmallQuery OnePointQuery(v1::FusionMap::Stub& stub) {
  v1::QueryPointsRequest request;
  *request.add_points() = P(kOnBoard);
  return {"QueryPoints, 1 point", [&stub, request](grpc::ClientContext* context) {
            v1::QueryPointsResponse reply;
            return stub.QueryPoints(context, request, &reply);
          }};
}

// Board-area points: some occupied, some free, some unknown.
SmallQuery TenPointsQuery(v1::FusionMap::Stub& stub) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> ux(0.3, 2.2), uy(-1.0, 1.0), uz(-0.45, 0.75);
  v1::QueryPointsRequest request;
  for (int i = 0; i < 10; ++i) *request.add_points() = P({ux(rng), uy(rng), uz(rng)});
  return {"QueryPoints, 10 points", [&stub, request](grpc::ClientContext* context) {
            v1::QueryPointsResponse reply;
            return stub.QueryPoints(context, request, &reply);
          }};
}

// Counts its hits in *hits (read it after the loop that issues the queries).
SmallQuery CastRayQuery(v1::FusionMap::Stub& stub, int* hits) {
  v1::CastRayRequest request;
  *request.mutable_origin() = P({0, 0, 0});
  *request.mutable_direction() = P({1, 0.05, 0.1});
  request.set_max_range_m(5);
  request.set_ignore_unknown(true);
  return {"CastRay (through unknown, 5 m)", [&stub, request, hits](grpc::ClientContext* context) {
            v1::CastRayResponse reply;
            const grpc::Status status = stub.CastRay(context, request, &reply);
            *hits += reply.hit() ? 1 : 0;
            return status;
          }};
}

// Issues the queries in rotation, one every 2 ms, while keep_going() holds; returns the latency
// (ms) of each successful call, per kind, and counts the failed calls in *errors.
std::vector<std::vector<double>> RunSmallQueries(const std::vector<SmallQuery>& queries,
                                                 const std::function<bool()>& keep_going,
                                                 int* errors) {
  std::vector<std::vector<double>> latency_ms(queries.size());
  auto next = Clock::now();
  for (std::size_t i = 0; keep_going(); ++i) {
    const std::size_t kind = i % queries.size();
    grpc::ClientContext context;
    context.set_deadline(In(1000ms));
    const auto t0 = Clock::now();
    const grpc::Status status = queries[kind].call(&context);
    const double ms = Ms(Clock::now() - t0);
    if (status.ok())
      latency_ms[kind].push_back(ms);
    else
      ++*errors;
    next += 2ms;
    std::this_thread::sleep_until(next);
  }
  return latency_ms;
}

std::vector<std::string> NamesOf(const std::vector<SmallQuery>& queries) {
  std::vector<std::string> names;
  for (const auto& query : queries) names.push_back(query.name);
  return names;
}

// One table row per query kind and one for all of them: samples, p50, p99, max (ms).
void PrintQueryRows(const char* label, const std::vector<std::string>& names,
                    const std::vector<std::vector<double>>& latency_ms) {
  const auto row = [label](const std::string& name, const std::vector<double>& v) {
    std::printf("| %s | %s | %zu | %.3f | %.3f | %.2f |\n", label, name.c_str(), v.size(),
                Percentile(v, 0.5), Percentile(v, 0.99),
                v.empty() ? NAN : *std::max_element(v.begin(), v.end()));
  };
  std::vector<double> combined;
  for (std::size_t k = 0; k < names.size(); ++k) {
    row(names[k], latency_ms[k]);
    combined.insert(combined.end(), latency_ms[k].begin(), latency_ms[k].end());
  }
  row("all small queries", combined);
}

struct BenchOptions {
  double seconds = 10;         // scenarios 3 and 4
  bool seconds_given = false;  // scenario 5 runs 20 s unless --seconds is given
  int trials = 20;
  std::string log_level = "warn";
  double max_range_m = 0.0;  // map.max_range_m; 0: each scenario's configuration decides
  std::string extra_config;
  std::string only = "1,2,3,4,5";
  [[nodiscard]] bool Runs(char scenario) const { return only.find(scenario) != std::string::npos; }
};

constexpr const char* kUsage =
    "usage: service_bench [--seconds S] [--trials N] [--log-level LEVEL] [--max-range M]\n"
    "                     [--config TEXT] [--only LIST]\n"
    "  --seconds   scenarios 3 and 4 (default 10) and 5 (default 20)\n"
    "  --trials    scenario 1's frames (default 20)\n"
    "  --log-level fusiond's (default warn; other levels write its log to /tmp)\n"
    "  --max-range map.max_range_m of every scenario\n"
    "  --config    more fusiond configuration (text format), merged over each scenario's\n"
    "  --only      scenarios to run, e.g. 1,3 (default 1,2,3,4,5; 2 and 3 need 1)\n"
    "Scenarios: 1 latency of one frame, 2 QueryPoints throughput, 3 small queries while\n"
    "streaming, 4 drops at 30 + 15 Hz, 5 the deployment's configuration while moving.\n";

bool ParseOptions(int argc, char** argv, BenchOptions* options) {
  if (argc % 2 == 0) {
    std::fprintf(stderr, "%s", kUsage);
    return false;
  }
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string flag = argv[i];
    if (flag == "--seconds") {
      options->seconds = std::atof(argv[i + 1]);
      options->seconds_given = true;
    } else if (flag == "--max-range") {
      options->max_range_m = std::atof(argv[i + 1]);
    } else if (flag == "--trials") {
      options->trials = std::atoi(argv[i + 1]);
    } else if (flag == "--log-level") {
      options->log_level = argv[i + 1];
    } else if (flag == "--config") {
      options->extra_config = argv[i + 1];
    } else if (flag == "--only") {
      options->only = argv[i + 1];
    } else {
      std::fprintf(stderr, "unknown flag %s\n", flag.c_str());
      return false;
    }
  }
  return true;
}

// A scenario's fusiond configuration text with --max-range and --config merged over it the
// way text format merges (scalars overwrite, sub-messages merge, sensors are appended). Plain
// concatenation would repeat "map { }", which fusiond refuses. Unchanged without those flags;
// nullopt (protobuf has printed why) if a text does not parse.
std::optional<std::string> WithBenchOverrides(const std::string& base_text,
                                              const BenchOptions& options) {
  if (options.max_range_m <= 0.0 && options.extra_config.empty()) return base_text;
  v1::ServiceConfig config;
  if (!google::protobuf::TextFormat::ParseFromString(base_text, &config)) return std::nullopt;
  if (options.max_range_m > 0.0) config.mutable_map()->set_max_range_m(options.max_range_m);
  if (!google::protobuf::TextFormat::MergeFromString(options.extra_config, &config))
    return std::nullopt;
  std::string text;
  google::protobuf::TextFormat::PrintToString(config, &text);
  return text;
}

std::string ReadFile(const std::string& path) {
  std::ifstream in(path);
  std::stringstream text;
  text << in.rdbuf();
  return text.str();
}

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

// ---- Scenarios 1 to 4: the paper's stationary sensors ---------------------------------------
int RunPaperScenarios(const BenchOptions& options, const std::string& dir, unsigned domain) {
  const double seconds = options.seconds;
  const int trials = options.trials;
  // Frames: the paper's two sensors looking at the board.
  sim::PaperRunOptions run_options;
  run_options.sr_frames = 30;
  run_options.stereo_frames = 30;
  const auto runs = sim::PaperSensorRuns(run_options);
  const sim::Scene scene = sim::PaperBoardScene();
  std::map<std::string, SensorStream> streams;
  for (const auto& run : runs)
    streams[run.id] = {run.id, run.T_world_sensor, sim::SimulateRun(scene, run)};
  const SensorStream& sr = streams.at("sr3000");
  const SensorStream& stoc = streams.at("stoc");
  std::printf("frames: sr3000 %d x %d (%zu bytes of xyz), stoc %d x %d (%zu bytes of xyz)\n\n",
              sr.frames[0].cols, sr.frames[0].rows, sr.frames[0].xyz.size() * 4,
              stoc.frames[0].cols, stoc.frames[0].rows, stoc.frames[0].xyz.size() * 4);
  const auto run = [&options](char scenario) { return options.Runs(scenario); };

  // fusiond with default map, ingest and limit settings (render_interval_ms 200).
  const std::string config = dir + "/fusiond.pbtxt";
  const auto config_text = WithBenchOverrides(
      "sensors { id: \"sr3000\" preset: \"sr3000\" }\n"
      "sensors { id: \"stoc\" preset: \"stoc\" cols: 160 rows: 120 }\n",
      options);
  if (!config_text) {
    std::fprintf(stderr, "bad --config text\n");
    return 2;
  }
  std::ofstream(config) << *config_text;
  FusiondProcess fusiond({"--config", config, "--listen", "127.0.0.1:0", "--dds-domain",
                          std::to_string(domain), "--log-level", options.log_level});
  if (!fusiond.Start()) return 1;
  std::printf("configuration:\n\n```\n%s```\n\n", ReadFile(config).c_str());
  Client client(fusiond.address());
  Publisher publisher(domain);
  if (!publisher.ok()) {
    std::fprintf(stderr, "publisher: %s\n", publisher.error().c_str());
    return 1;
  }
  const dds_entity_t sr_writer = publisher.CreateWriter();
  const dds_entity_t stoc_writer = publisher.CreateWriter();
  if (sr_writer < 0 || stoc_writer < 0 || !Publisher::WaitForReader(sr_writer, 10s) ||
      !Publisher::WaitForReader(stoc_writer, 10s)) {
    std::fprintf(stderr, "no DDS reader matched\n");
    return 1;
  }
  std::uint64_t sr_seq = 0, stoc_seq = 0;

  // ---- 1. DDS-to-queryable latency of one SR-3000 frame --------------------------------
  // Writes one frame at t0 and waits for the next map version on a StreamUpdates subscription
  // (a version is queryable once published, and the stream carries it right after); a
  // QueryPoints on a board voxel then confirms that version answers (and, after a reset, shows
  // the board). Nothing else is published, so the first newer version is the render that
  // contains the frame. Polling QueryPoints instead would itself load the 2 cores.
  const auto frame_to_queryable = [&](VersionWatcher& watcher, std::uint64_t after_version,
                                      bool need_board,
                                      const sim::OrganizedCloud& frame) -> double {
    const auto t0 = Clock::now();
    Publisher::Write(sr_writer, sr.id, ++sr_seq, sr.pose, frame);
    while (Clock::now() - t0 < 3s) {
      const auto arrival = watcher.FirstAfter(after_version, 3000ms);
      if (!arrival) break;
      grpc::ClientContext context;
      context.set_deadline(In(1000ms));
      v1::QueryPointsRequest request;
      *request.add_points() = P(kOnBoard);
      v1::QueryPointsResponse reply;
      if (client.stub().QueryPoints(&context, request, &reply).ok() &&
          reply.map_version() >= arrival->first && reply.results_size() == 1 &&
          (!need_board || reply.results(0).state() != v1::VOXEL_STATE_UNKNOWN)) {
        return Ms(arrival->second - t0);
      }
      after_version = arrival->first;  // not this one: the next
    }
    return -1;  // lost (best effort) or no visible change
  };
  const auto current_version = [&] {
    v1::Stats stats;
    return client.Stats(&stats) ? stats.map_version() : 0;
  };
  const auto latency_row = [](const char* name, const std::vector<double>& v) {
    if (v.empty()) return;
    std::printf("| %s | %zu | %.1f | %.1f | %.1f | %.1f |\n", name, v.size(), Percentile(v, 0.5),
                Percentile(v, 0.9), *std::max_element(v.begin(), v.end()),
                *std::min_element(v.begin(), v.end()));
  };
  if (run('1')) {
    std::printf(
        "## 1. DDS-to-queryable latency, one SR-3000 frame (176 x 144), "
        "render_interval_ms 200 (default)\n\n");
    std::printf(
        "| case | trials | median ms | p90 ms | max ms | min ms |\n"
        "|---|---|---|---|---|---|\n");
    int timeouts = 0;
    // 1a. First frame after ResetMap (every voxel of the frustum is new), worker idle.
    std::vector<double> after_reset;
    for (int t = 0; t < std::max(3, trials / 4); ++t) {
      const std::uint64_t reset_version = client.Reset();
      VersionWatcher watcher(client.stub(), reset_version);
      std::this_thread::sleep_for(250ms);
      const double ms =
          frame_to_queryable(watcher, reset_version, true, sr.frames[t % sr.frames.size()]);
      if (ms < 0)
        ++timeouts;
      else
        after_reset.push_back(ms);
    }
    latency_row("first frame after ResetMap (worker idle)", after_reset);
    // Map the board with both sensors (steady state for the rest of the benchmark).
    for (int i = 0; i < 15; ++i) {
      Publisher::Write(sr_writer, sr.id, ++sr_seq, sr.pose, sr.frames[i % sr.frames.size()]);
      Publisher::Write(stoc_writer, stoc.id, ++stoc_seq, stoc.pose,
                       stoc.frames[i % stoc.frames.size()]);
      std::this_thread::sleep_for(33ms);
    }
    std::uint64_t version = 0;
    for (int i = 0; i < 50; ++i) {  // until the worker is idle: no new version for 600 ms
      std::this_thread::sleep_for(600ms);
      const std::uint64_t v = current_version();
      if (v == version) break;
      version = v;
    }
    // 1b. Steady state: one more frame of the same stationary sensor into a mapped scene. The
    // gap after the previous render spreads over 0..250 ms: frames with a gap < 200 ms wait
    // for the render cadence, the others are rendered as soon as they are integrated.
    std::vector<double> all, idle, cadence;
    VersionWatcher watcher(client.stub(), version);
    for (int t = 0; t < trials; ++t) {
      const auto gap = std::chrono::microseconds(250000 * t / std::max(1, trials - 1));
      std::this_thread::sleep_for(gap);
      const double ms =
          frame_to_queryable(watcher, version, false, sr.frames[t % sr.frames.size()]);
      if (ms < 0) {
        ++timeouts;
        std::this_thread::sleep_for(1000ms);
      } else {
        all.push_back(ms);
        (gap >= 200ms ? idle : cadence).push_back(ms);
      }
      version = current_version();
    }
    latency_row("mapped scene, all trials", all);
    latency_row("mapped scene, gap < 200 ms after previous render", cadence);
    latency_row("mapped scene, gap >= 200 ms (worker idle)", idle);
    std::printf("\ntimeouts (frame lost or no new version within 3 s): %d; target: <= 200 ms\n\n",
                timeouts);
    v1::Stats stats;
    if (client.Stats(&stats)) {
      std::printf("map for the query scenarios: version %llu, %llu leaves, %llu bytes\n\n",
                  static_cast<unsigned long long>(stats.map_version()),
                  static_cast<unsigned long long>(stats.map_leaves()),
                  static_cast<unsigned long long>(stats.map_memory_bytes()));
    }
  }

  // ---- 2. Batched QueryPoints throughput -----------------------------------------------
  if (run('2')) {
    std::printf(
        "## 2. QueryPoints throughput (one client, end to end incl. client-side "
        "protobuf; random points in the box [0.3,2.2] x [-1,1] x [-0.45,0.75] m)\n\n");
    std::mt19937 rng(5);
    std::uniform_real_distribution<double> ux(0.3, 2.2), uy(-1.0, 1.0), uz(-0.45, 0.75);
    v1::QueryPointsRequest big;
    for (int i = 0; i < 100000; ++i) *big.add_points() = P({ux(rng), uy(rng), uz(rng)});
    std::printf(
        "| batch (points) | clients | calls | ms per call (median) | points/s |\n"
        "|---|---|---|---|---|\n");
    for (const auto& [batch, clients] :
         std::vector<std::pair<int, int>>{{10000, 1}, {50000, 1}, {100000, 1}, {100000, 2}}) {
      v1::QueryPointsRequest request;
      request.mutable_points()->CopyFrom(big.points());
      request.mutable_points()->DeleteSubrange(batch, big.points_size() - batch);
      std::vector<std::vector<double>> per_call(static_cast<std::size_t>(clients));
      std::atomic<std::uint64_t> points{0};
      std::atomic<int> errors{0};
      const auto start = Clock::now();
      std::vector<std::thread> threads;
      for (int c = 0; c < clients; ++c) {
        threads.emplace_back([&, c] {
          while (Clock::now() - start < 1500ms || per_call[c].size() < 3) {
            grpc::ClientContext context;
            context.set_deadline(In(10000ms));
            v1::QueryPointsResponse reply;
            const auto t0 = Clock::now();
            const auto status = client.stub().QueryPoints(&context, request, &reply);
            if (!status.ok() || reply.results_size() != batch) {
              if (errors++ == 0)
                std::fprintf(stderr, "QueryPoints: %s\n", status.error_message().c_str());
              continue;
            }
            per_call[c].push_back(Ms(Clock::now() - t0));
            points += static_cast<std::uint64_t>(batch);
          }
        });
      }
      for (auto& t : threads) t.join();
      const double elapsed = std::chrono::duration<double>(Clock::now() - start).count();
      std::vector<double> calls;
      for (const auto& v : per_call) calls.insert(calls.end(), v.begin(), v.end());
      std::printf("| %d | %d | %zu | %.1f | %.2fM |%s\n", batch, clients, calls.size(),
                  Percentile(calls, 0.5), static_cast<double>(points) / elapsed / 1e6,
                  errors > 0 ? " errors!" : "");
    }
    std::printf("\ntarget: >= 1M points/s\n\n");
  }

  // ---- 3. Small-query latency while two sensors stream at 30 Hz -------------------------
  std::map<std::string, v1::SensorCounters> before, after;
  if (run('3')) {
    std::printf(
        "## 3. Small-query latency while sr3000 (176 x 144) and stoc (160 x 120) "
        "stream at 30 Hz each, %.0f s, one query every 2 ms (rotating kinds)\n\n",
        seconds);
    int hits = 0;  // counted by the CastRay query
    const std::vector<SmallQuery> queries = {OnePointQuery(client.stub()),
                                             TenPointsQuery(client.stub()),
                                             CastRayQuery(client.stub(), &hits)};
    // Queries of rotating kinds every 2 ms for `duration`; prints one row per kind.
    const auto run_queries = [&](double duration, const char* label) {
      int errors = 0;
      hits = 0;
      const auto start = Clock::now();
      const auto latency_ms = RunSmallQueries(
          queries, [&] { return Clock::now() - start < std::chrono::duration<double>(duration); },
          &errors);
      PrintQueryRows(label, NamesOf(queries), latency_ms);
      return std::pair{errors, hits};
    };
    std::printf(
        "| sensors | query | samples | p50 ms | p99 ms | max ms |\n"
        "|---|---|---|---|---|---|\n");
    const auto [idle_errors, idle_hits] = run_queries(2.0, "none (baseline, 2 s)");
    client.Counters(&before);
    std::atomic<bool> stop{false};
    StreamStats sr_stats, stoc_stats;  // one per thread
    std::thread sr_thread([&] { sr_stats = Stream(sr_writer, sr, 30, &sr_seq, stop); });
    std::thread stoc_thread([&] { stoc_stats = Stream(stoc_writer, stoc, 30, &stoc_seq, stop); });
    const auto [errors, ray_hits] = run_queries(seconds, "2 x 30 Hz");
    stop = true;
    sr_thread.join();
    stoc_thread.join();
    const std::map<std::string, StreamStats> published{{"sr3000", sr_stats}, {"stoc", stoc_stats}};
    std::printf(
        "\nerrors: %d (baseline %d); CastRay hits: %d (baseline %d); target p99 <= 2 ms "
        "while streaming\n\n",
        errors, idle_errors, ray_hits, idle_hits);
    std::this_thread::sleep_for(1000ms);  // let the worker drain its queues
    client.Counters(&after);
    std::printf("counters during scenario 3:\n\n");
    PrintCounterTable({{"sr3000", 30}, {"stoc", 30}}, published, before, after);
    std::printf("\n");
  }

  // ---- 4. Samples dropped: sr3000 at 30 Hz + stoc at 15 Hz -----------------------------
  if (run('4')) {
    std::printf(
        "## 4. Samples lost with sr3000 (176 x 144) at 30 Hz + stoc (160 x 120) at "
        "15 Hz, %.0f s, no queries\n\n",
        seconds);
    v1::Stats stats_before, stats_after;
    client.Stats(&stats_before);
    client.Counters(&before);
    std::atomic<bool> stop{false};
    StreamStats sr_stats, stoc_stats;  // one per thread
    std::thread sr_thread([&] { sr_stats = Stream(sr_writer, sr, 30, &sr_seq, stop); });
    std::thread stoc_thread([&] { stoc_stats = Stream(stoc_writer, stoc, 15, &stoc_seq, stop); });
    std::this_thread::sleep_for(std::chrono::duration<double>(seconds));
    stop = true;
    sr_thread.join();
    stoc_thread.join();
    const std::map<std::string, StreamStats> published{{"sr3000", sr_stats}, {"stoc", stoc_stats}};
    std::this_thread::sleep_for(1000ms);
    client.Counters(&after);
    client.Stats(&stats_after);
    PrintCounterTable({{"sr3000", 30}, {"stoc", 15}}, published, before, after);
    std::printf("\nrenders during the run: %llu (%.1f per s)\n\n",
                static_cast<unsigned long long>(stats_after.renders() - stats_before.renders()),
                static_cast<double>(stats_after.renders() - stats_before.renders()) / seconds);
  }

  const int code = fusiond.Stop(options.log_level, "/tmp/service_bench_fusiond.log");
  std::printf("fusiond (scenarios 1-4) exit code %d\n\n", code);
  return 0;
}

// ---- 5. The service keeps up while moving -------------------------------------------------

// The deployment's configuration (docker/fusiond.pbtxt, beside this file's tests/ folder).
const std::string kDeploymentConfig =
    std::filesystem::path(__FILE__).parent_path().parent_path().parent_path().parent_path() /
    "docker" / "fusiond.pbtxt";

// A waypoint of the rig (the SR-3000's optical frame): time, position in the world, yaw to the
// left (no pitch).
struct Waypoint {
  double t_s, x_m, y_m, z_m, yaw_deg;
};

// One lap of 10 s from the paper's mounting (the origin, looking along +x): forward 0.85 m
// while yawing to +20 deg, then back while yawing back: 0.17 m/s and 4 deg/s, 1.7 m per lap.
// The board (x = 1.75 m) stays at least 0.9 m ahead. Longer runs repeat the lap.
const std::vector<Waypoint> kLap = {
    {0.0, 0.0, 0.0, 0.0, 0.0}, {5.0, 0.85, 0.0, 0.0, 20.0}, {10.0, 0.0, 0.0, 0.0, 0.0}};

// The SR-3000's pose at t_s: the lap's waypoints, linearly interpolated.
Eigen::Isometry3d RigPoseAt(double t_s) {
  const double lap_t_s = std::fmod(t_s, kLap.back().t_s);
  std::size_t i = 1;
  while (i + 1 < kLap.size() && lap_t_s > kLap[i].t_s) ++i;
  const Waypoint& a = kLap[i - 1];
  const Waypoint& b = kLap[i];
  const double f = (lap_t_s - a.t_s) / (b.t_s - a.t_s);
  const auto mix = [f](double u, double v) { return u + f * (v - u); };
  constexpr double kRadPerDeg = M_PI / 180.0;
  const Eigen::Vector3d position_m(mix(a.x_m, b.x_m), mix(a.y_m, b.y_m), mix(a.z_m, b.z_m));
  return sim::ForwardLookingPose(position_m, mix(a.yaw_deg, b.yaw_deg) * kRadPerDeg);
}

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

MovingSensor SimulateOnPath(const sim::Scene& scene, const sim::SensorRun& run,
                            const Eigen::Isometry3d& T_rig_sensor, double rate_hz, double seconds) {
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
std::vector<MovingSensor> SimulateMovingSensors(double seconds) {
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
StreamStats PublishOnPath(dds_entity_t writer, const MovingSensor& sensor, Clock::time_point start,
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
QueryableLatencies QueryableLatenciesOf(
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

// Polls GetStats until clouds_in_map reaches clouds_received (and clouds_received reaches the
// clouds written, or a second has passed for the last ones in flight); returns the wait in ms,
// or -1 when `timeout` passed first. *stats: the last answer.
double WaitUntilAllCloudsInMap(Client& client, std::uint64_t clouds_written,
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

// ListSensors' `merged` counter (clouds integrated while the renderer was behind), where this
// build's proto has one.
std::optional<std::uint64_t> MergedCounter(const v1::SensorCounters& counters) {
  const auto* field = counters.GetDescriptor()->FindFieldByName("merged");
  if (field == nullptr || field->is_repeated() ||
      field->cpp_type() != google::protobuf::FieldDescriptor::CPPTYPE_UINT64) {
    return std::nullopt;
  }
  return counters.GetReflection()->GetUInt64(counters, field);
}

// A "Vm..." line of /proc/<pid>/status in MB (-1 if absent).
double ProcStatusMb(pid_t pid, const std::string& field) {
  std::ifstream in("/proc/" + std::to_string(pid) + "/status");
  for (std::string line; std::getline(in, line);) {
    if (line.rfind(field + ":", 0) == 0) return std::atof(line.c_str() + field.size() + 1) / 1024;
  }
  return -1;
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
DriveResult Drive(Client& client, const std::vector<MovingSensor>& sensors,
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

void PrintCountersAndCompleteness(const DriveResult& r, const std::vector<MovingSensor>& sensors) {
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

void PrintQueryableLatencies(const DriveResult& r, const std::vector<MovingSensor>& sensors) {
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

void PrintSmallQueries(const DriveResult& r) {
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
std::unique_ptr<octomap::OcTree> BuildOctoMapBaseline(const std::vector<MovingSensor>& sensors,
                                                      double resolution_m, double max_range_m) {
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

FusiondMemory ReadFusiondMemory(Client& client, pid_t pid) {
  FusiondMemory memory;
  (void)client.Stats(&memory.stats);
  memory.rss_mb = ProcStatusMb(pid, "VmRSS");
  memory.peak_rss_mb = ProcStatusMb(pid, "VmHWM");
  return memory;
}

void CompareMemory(const FusiondMemory& fusiond, const std::vector<MovingSensor>& sensors,
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
bool MovingConfig(const BenchOptions& options, const std::string& dir, std::string* path,
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

bool CreateWriters(Publisher& publisher, std::size_t count, std::vector<dds_entity_t>* writers) {
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

int RunMovingScenario(const BenchOptions& options, const std::string& dir, unsigned domain) {
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

}  // namespace

int main(int argc, char** argv) {
  BenchOptions options;
  if (argc == 2 && std::string(argv[1]) == "--help") {
    std::printf("%s", kUsage);
    return 0;
  }
  if (!ParseOptions(argc, argv, &options)) return 2;
  const auto bench_start = Clock::now();
  std::printf(
      "# fusiond service benchmark\n\nload average at start (/proc/loadavg): %s; "
      "hardware threads: %u\n\n",
      LoadAverage().c_str(), std::thread::hardware_concurrency());
  char dir_template[] = "/tmp/service_bench_XXXXXX";
  const char* dir = mkdtemp(dir_template);
  if (dir == nullptr) return 1;
  const unsigned domain = 100 + static_cast<unsigned>(getpid()) % 100;
  int code = 0;
  if (options.Runs('1') || options.Runs('2') || options.Runs('3') || options.Runs('4'))
    code = RunPaperScenarios(options, dir, domain);
  // Scenario 5 starts a fusiond of its own, in the same domain once the first one has exited.
  if (code == 0 && options.Runs('5')) code = RunMovingScenario(options, dir, domain);
  std::printf("load average at end: %s; total %.1f s\n", LoadAverage().c_str(),
              std::chrono::duration<double>(Clock::now() - bench_start).count());
  std::filesystem::remove_all(dir);
  return code;
}
