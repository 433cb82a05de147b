// fusiond end-to-end performance (issue 5): a real fusiond process on 127.0.0.1:0 in a private
// DDS domain, fed over DDS with simulated clouds of the paper's board scene by publisher
// threads in this process, queried over gRPC on loopback. Prints one table per scenario:
//   1. DDS-to-queryable latency of one SR-3000 frame (176 x 144) at the default render cadence
//   2. batched QueryPoints throughput
//   3. small-query latency (QueryPoints of 1 and 10 points, CastRay) while sr3000 and stoc
//      stream at 30 Hz each
//   4. samples dropped with sr3000 at 30 Hz and stoc (160 x 120) at 15 Hz
// Usage: service_bench [--seconds S] [--trials N] [--log-level LEVEL] [--max-range M]
//                      [--config TEXT] [--only LIST]
//   --seconds: duration of scenarios 3 and 4 (default 10); --trials: scenario 1 (default 20);
//   --log-level: fusiond's (default warn; debug logs render times, written to
//   /tmp/service_bench_fusiond.log); --max-range: map.max_range_m; --config: more fusiond
//   configuration (text format, e.g. "map { render_threads: 1 }"); --only: scenarios to run,
//   e.g. 1,3 (default all; 2 and 3 need the board mapped by 1).
#include <grpcpp/grpcpp.h>
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
#include "fusion/service/dds_domain.h"
#include "fusion/sim/experiment.h"
#include "fusion/sim/scene.h"
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
    participant_ = fusion::service::CreateParticipant(domain, &error_);
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

}  // namespace

int main(int argc, char** argv) {
  double seconds = 10;
  int trials = 20;
  std::string log_level = "warn";
  double max_range_m = 0.0;  // map.max_range_m; 0: the default (each sensor's full range)
  std::string extra_config;
  std::string only = "1,2,3,4";
  if (argc % 2 == 0) {
    std::fprintf(stderr, "usage: see the comment at the top of service_bench.cc\n");
    return 2;
  }
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string flag = argv[i];
    if (flag == "--seconds")
      seconds = std::atof(argv[i + 1]);
    else if (flag == "--max-range")
      max_range_m = std::atof(argv[i + 1]);
    else if (flag == "--trials")
      trials = std::atoi(argv[i + 1]);
    else if (flag == "--log-level")
      log_level = argv[i + 1];
    else if (flag == "--config")
      extra_config = argv[i + 1];
    else if (flag == "--only")
      only = argv[i + 1];
    else {
      std::fprintf(stderr, "unknown flag %s\n", flag.c_str());
      return 2;
    }
  }
  const auto bench_start = Clock::now();
  std::printf(
      "# fusiond service benchmark\n\nload average at start (/proc/loadavg): %s; "
      "hardware threads: %u\n\n",
      LoadAverage().c_str(), std::thread::hardware_concurrency());

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

  // fusiond with default map, ingest and limit settings (render_interval_ms 200).
  char dir_template[] = "/tmp/service_bench_XXXXXX";
  const char* dir = mkdtemp(dir_template);
  if (dir == nullptr) return 1;
  const std::string config = std::string(dir) + "/fusiond.pbtxt";
  std::ofstream(config) << "sensors { id: \"sr3000\" preset: \"sr3000\" }\n"
                        << "sensors { id: \"stoc\" preset: \"stoc\" cols: 160 rows: 120 }\n";
  if (max_range_m > 0.0)
    std::ofstream(config, std::ios::app) << "map { max_range_m: " << max_range_m << " }\n";
  if (!extra_config.empty()) std::ofstream(config, std::ios::app) << extra_config << "\n";
  const auto run = [&only](char scenario) { return only.find(scenario) != std::string::npos; };
  const unsigned domain = 100 + static_cast<unsigned>(getpid()) % 100;
  // fusiond logs on stderr: through a shell that joins it to stdout, which Subprocess reads.
  fusion::testing::Subprocess fusiond(
      {"/bin/sh", "-c", "exec \"$0\" \"$@\" 2>&1", kFusiond, "--config", config, "--listen",
       "127.0.0.1:0", "--dds-domain", std::to_string(domain), "--log-level", log_level});
  const auto port = fusiond.WaitForOutput(R"(listening on 127\.0\.0\.1:(\d+))", 20s);
  if (!port) {
    std::fprintf(stderr, "fusiond did not start: %s\n", fusiond.output().c_str());
    return 1;
  }
  std::printf(
      "fusiond: %s --config %s --listen 127.0.0.1:0 --dds-domain %u --log-level %s "
      "(port %s)\n\n",
      kFusiond.c_str(), config.c_str(), domain, log_level.c_str(), port->c_str());
  {
    std::ifstream in(config);
    std::stringstream text;
    text << in.rdbuf();
    std::printf("configuration:\n\n```\n%s```\n\n", text.str().c_str());
  }
  Client client("127.0.0.1:" + *port);
  // fusiond logs to its stdout (spdlog's default logger): keep draining the pipe so verbose
  // levels cannot block it, and keep the text for the end.
  std::atomic<bool> drain_stop{false};
  std::thread drain([&] {
    while (!drain_stop) (void)fusiond.WaitForOutput("(?!)", 100ms);
  });

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
    // Board-area points: some occupied, some free, some unknown.
    std::mt19937 rng(11);
    std::uniform_real_distribution<double> ux(0.3, 2.2), uy(-1.0, 1.0), uz(-0.45, 0.75);
    v1::QueryPointsRequest one, ten;
    *one.add_points() = P(kOnBoard);
    for (int i = 0; i < 10; ++i) *ten.add_points() = P({ux(rng), uy(rng), uz(rng)});
    v1::CastRayRequest ray;
    *ray.mutable_origin() = P({0, 0, 0});
    *ray.mutable_direction() = P({1, 0.05, 0.1});
    ray.set_max_range_m(5);
    ray.set_ignore_unknown(true);
    const char* names[3] = {"QueryPoints, 1 point", "QueryPoints, 10 points",
                            "CastRay (through unknown, 5 m)"};
    // Queries of rotating kinds every 2 ms for `duration`; prints one row per kind.
    const auto run_queries = [&](double duration, const char* label) {
      std::vector<double> lat[3];
      int errors = 0, ray_hits = 0;
      const auto start = Clock::now();
      auto next = start;
      for (int i = 0; Clock::now() - start < std::chrono::duration<double>(duration); ++i) {
        grpc::ClientContext context;
        context.set_deadline(In(1000ms));
        const auto t0 = Clock::now();
        grpc::Status status;
        if (i % 3 == 0) {
          v1::QueryPointsResponse reply;
          status = client.stub().QueryPoints(&context, one, &reply);
        } else if (i % 3 == 1) {
          v1::QueryPointsResponse reply;
          status = client.stub().QueryPoints(&context, ten, &reply);
        } else {
          v1::CastRayResponse reply;
          status = client.stub().CastRay(&context, ray, &reply);
          ray_hits += reply.hit() ? 1 : 0;
        }
        const double ms = Ms(Clock::now() - t0);
        if (status.ok())
          lat[i % 3].push_back(ms);
        else
          ++errors;
        next += 2ms;
        std::this_thread::sleep_until(next);
      }
      std::vector<double> combined;
      for (int k = 0; k < 3; ++k) {
        combined.insert(combined.end(), lat[k].begin(), lat[k].end());
        std::printf("| %s | %s | %zu | %.3f | %.3f | %.2f |\n", label, names[k], lat[k].size(),
                    Percentile(lat[k], 0.5), Percentile(lat[k], 0.99),
                    lat[k].empty() ? NAN : *std::max_element(lat[k].begin(), lat[k].end()));
      }
      std::printf("| %s | all small queries | %zu | %.3f | %.3f | %.2f |\n", label, combined.size(),
                  Percentile(combined, 0.5), Percentile(combined, 0.99),
                  combined.empty() ? NAN : *std::max_element(combined.begin(), combined.end()));
      return std::pair{errors, ray_hits};
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

  drain_stop = true;
  drain.join();
  const int code = fusiond.Stop(SIGTERM, 10s);
  (void)fusiond.WaitForOutput("(?!)", 500ms);
  if (log_level != "warn") {
    const std::string log = "/tmp/service_bench_fusiond.log";
    std::ofstream(log) << fusiond.output();
    std::printf("fusiond output (log level %s) written to %s\n", log_level.c_str(), log.c_str());
  } else if (fusiond.output().find("[warn") != std::string::npos ||
             fusiond.output().find("[error") != std::string::npos) {
    std::printf("fusiond warnings:\n%s\n", fusiond.output().c_str());
  }
  std::printf("fusiond exit code %d; load average at end: %s; total %.1f s\n", code,
              LoadAverage().c_str(),
              std::chrono::duration<double>(Clock::now() - bench_start).count());
  std::filesystem::remove_all(dir);
  return 0;
}
