// service_bench (service_bench.cc), scenarios 1 to 4: the paper's two stationary sensors looking
// at the board, one fusiond with the default configuration:
//   1. DDS-to-queryable latency of one SR-3000 frame, 2. batched QueryPoints throughput,
//   3. small-query latency while both sensors stream at 30 Hz, 4. clouds dropped at 30 + 15 Hz.
#pragma once

#include <grpcpp/grpcpp.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <fstream>
#include <functional>
#include <map>
#include <memory>
#include <random>
#include <string>
#include <thread>
#include <tuple>
#include <utility>
#include <vector>

#include "fusion/service/config.h"
#include "fusion/sim/experiment.h"
#include "fusion/sim/scene.h"
#include "fusion/sim/simulator.h"
#include "fusion/v1/map_service.grpc.pb.h"
#include "service_bench_common.h"
#include "service_bench_fusiond.h"
#include "service_bench_queries.h"

namespace fusion::service_bench {

// The fusiond, its client and the two sensors' streams shared by scenarios 1 to 4, which run
// one after the other on the same map (2 and 3 query the board that 1 mapped).
class PaperScenarios {
 public:
  PaperScenarios(const BenchOptions& options, const std::string& dir, unsigned domain)
      : options_(options), dir_(dir), domain_(domain) {}

  // Simulates the frames, starts fusiond and matches a DDS writer per sensor to its reader;
  // 0, or the exit code (2: bad --config text, 1: fusiond or DDS did not come up).
  int Start() {
    SimulateFrames();
    const std::string config = dir_ + "/fusiond.pbtxt";
    // fusiond with default map, ingest and limit settings.
    const auto config_text = WithBenchOverrides(
        "sensors { id: \"sr3000\" preset: \"sr3000\" }\n"
        "sensors { id: \"stoc\" preset: \"stoc\" cols: 160 rows: 120 }\n",
        options_);
    if (!config_text) {
      std::fprintf(stderr, "bad --config text\n");
      return 2;
    }
    std::ofstream(config) << *config_text;
    v1::ServiceConfig parsed;
    if (google::protobuf::TextFormat::ParseFromString(*config_text, &parsed) &&
        parsed.map().render_interval_ms() != 0) {
      render_interval_ms_ = parsed.map().render_interval_ms();
    }
    fusiond_ = std::make_unique<FusiondProcess>(
        std::vector<std::string>{"--config", config, "--listen", "127.0.0.1:0", "--dds-domain",
                                 std::to_string(domain_), "--log-level", options_.log_level});
    if (!fusiond_->Start()) return 1;
    std::printf("configuration:\n\n```\n%s```\n\n", ReadFile(config).c_str());
    client_ = std::make_unique<Client>(fusiond_->address());
    publisher_ = std::make_unique<Publisher>(domain_);
    if (!publisher_->ok()) {
      std::fprintf(stderr, "publisher: %s\n", publisher_->error().c_str());
      return 1;
    }
    sr_writer_ = publisher_->CreateWriter();
    stoc_writer_ = publisher_->CreateWriter();
    if (sr_writer_ < 0 || stoc_writer_ < 0 || !Publisher::WaitForReader(sr_writer_, 10s) ||
        !Publisher::WaitForReader(stoc_writer_, 10s)) {
      std::fprintf(stderr, "no DDS reader matched\n");
      return 1;
    }
    return 0;
  }

  // ---- 1. DDS-to-queryable latency of one SR-3000 frame --------------------------------
  void LatencyOfOneFrame() {
    std::printf(
        "## 1. DDS-to-queryable latency, one SR-3000 frame (176 x 144), render_interval_ms %u\n\n",
        render_interval_ms_);
    std::printf(
        "| case | trials | median ms | p90 ms | max ms | min ms |\n"
        "|---|---|---|---|---|---|\n");
    int timeouts = 0;
    LatencyRow("first frame after ResetMap (worker idle)", LatenciesAfterReset(&timeouts));
    const std::uint64_t version = MapTheBoard();
    LatenciesInMappedScene(version, &timeouts);
    std::printf("\ntimeouts (frame lost or no new version within 3 s): %d; target: <= 200 ms\n\n",
                timeouts);
    v1::Stats stats;
    if (client_->Stats(&stats)) {
      std::printf("map for the query scenarios: version %llu, %llu leaves, %llu bytes\n\n",
                  static_cast<unsigned long long>(stats.map_version()),
                  static_cast<unsigned long long>(stats.map_leaves()),
                  static_cast<unsigned long long>(stats.map_memory_bytes()));
    }
  }

  // ---- 2. Batched QueryPoints throughput -----------------------------------------------
  void QueryPointsThroughput() {
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
      ThroughputRow(request, batch, clients);
    }
    std::printf("\ntarget: >= 1M points/s\n\n");
  }

  // ---- 3. Small-query latency while two sensors stream at 30 Hz -------------------------
  void SmallQueriesWhileStreaming() {
    const double seconds = options_.seconds;
    std::printf(
        "## 3. Small-query latency while sr3000 (176 x 144) and stoc (160 x 120) "
        "stream at 30 Hz each, %.0f s, one query every 2 ms (rotating kinds)\n\n",
        seconds);
    int hits = 0;  // counted by the CastRay query
    const std::vector<SmallQuery> queries = {OnePointQuery(client_->stub()),
                                             TenPointsQuery(client_->stub()),
                                             CastRayQuery(client_->stub(), &hits)};
    // Queries of rotating kinds every 2 ms for `duration_s`; prints one row per kind.
    const auto run_queries = [&](double duration_s, const char* label) {
      int errors = 0;
      hits = 0;
      const auto start = Clock::now();
      const auto latency_ms = RunSmallQueries(
          queries, [&] { return Clock::now() - start < std::chrono::duration<double>(duration_s); },
          &errors);
      PrintQueryRows(label, NamesOf(queries), latency_ms);
      return std::pair{errors, hits};
    };
    std::printf(
        "| sensors | query | samples | p50 ms | p99 ms | max ms |\n"
        "|---|---|---|---|---|---|\n");
    const auto [idle_errors, idle_hits] = run_queries(2.0, "none (baseline, 2 s)");
    client_->Counters(&before_);
    int errors = 0, ray_hits = 0;
    const auto published = StreamWhile(
        30, 30, [&] { std::tie(errors, ray_hits) = run_queries(seconds, "2 x 30 Hz"); });
    std::printf(
        "\nerrors: %d (baseline %d); CastRay hits: %d (baseline %d); target p99 <= 2 ms "
        "while streaming\n\n",
        errors, idle_errors, ray_hits, idle_hits);
    std::this_thread::sleep_for(1000ms);  // let the worker drain its queues
    client_->Counters(&after_);
    std::printf("counters during scenario 3:\n\n");
    PrintCounterTable({{"sr3000", 30}, {"stoc", 30}}, published, before_, after_);
    std::printf("\n");
  }

  // ---- 4. Samples dropped: sr3000 at 30 Hz + stoc at 15 Hz -----------------------------
  void DropsAt30And15Hz() {
    const double seconds = options_.seconds;
    std::printf(
        "## 4. Samples lost with sr3000 (176 x 144) at 30 Hz + stoc (160 x 120) at "
        "15 Hz, %.0f s, no queries\n\n",
        seconds);
    v1::Stats stats_before, stats_after;
    client_->Stats(&stats_before);
    client_->Counters(&before_);
    const auto published = StreamWhile(
        30, 15, [seconds] { std::this_thread::sleep_for(std::chrono::duration<double>(seconds)); });
    std::this_thread::sleep_for(1000ms);
    client_->Counters(&after_);
    client_->Stats(&stats_after);
    PrintCounterTable({{"sr3000", 30}, {"stoc", 15}}, published, before_, after_);
    std::printf("\nrenders during the run: %llu (%.1f per s)\n\n",
                static_cast<unsigned long long>(stats_after.renders() - stats_before.renders()),
                static_cast<double>(stats_after.renders() - stats_before.renders()) / seconds);
  }

  // SIGTERM to fusiond; its exit code.
  int Stop() { return fusiond_->Stop(options_.log_level, "/tmp/service_bench_fusiond.log"); }

 private:
  // The paper's two sensors looking at the board, 30 frames each.
  void SimulateFrames() {
    sim::PaperRunOptions run_options;
    run_options.sr_frames = 30;
    run_options.stereo_frames = 30;
    const auto runs = sim::PaperSensorRuns(run_options);
    const sim::Scene scene = sim::PaperBoardScene();
    for (const auto& run : runs)
      streams_[run.id] = {run.id, run.T_world_sensor, sim::SimulateRun(scene, run)};
    const SensorStream& sr = Sr();
    const SensorStream& stoc = Stoc();
    std::printf("frames: sr3000 %d x %d (%zu bytes of xyz), stoc %d x %d (%zu bytes of xyz)\n\n",
                sr.frames[0].cols, sr.frames[0].rows, sr.frames[0].xyz.size() * 4,
                stoc.frames[0].cols, stoc.frames[0].rows, stoc.frames[0].xyz.size() * 4);
  }
  const SensorStream& Sr() const { return streams_.at("sr3000"); }
  const SensorStream& Stoc() const { return streams_.at("stoc"); }

  std::uint64_t CurrentVersion() {
    v1::Stats stats;
    return client_->Stats(&stats) ? stats.map_version() : 0;
  }

  static void LatencyRow(const char* name, const std::vector<double>& v) {
    if (v.empty()) return;
    std::printf("| %s | %zu | %.1f | %.1f | %.1f | %.1f |\n", name, v.size(), Percentile(v, 0.5),
                Percentile(v, 0.9), *std::max_element(v.begin(), v.end()),
                *std::min_element(v.begin(), v.end()));
  }

  // Writes one frame at t0 and waits for the next map version on a StreamUpdates subscription
  // (a version is queryable once published, and the stream carries it right after); a
  // QueryPoints on a board voxel then confirms that version answers (and, after a reset, shows
  // the board). Nothing else is published, so the first newer version is the render that
  // contains the frame. Polling QueryPoints instead would itself load the 2 cores. The
  // latency in ms, or -1: lost (best effort) or no visible change within 3 s.
  double FrameToQueryableMs(VersionWatcher& watcher, std::uint64_t after_version, bool need_board,
                            const sim::OrganizedCloud& frame) {
    const SensorStream& sr = Sr();
    const auto t0 = Clock::now();
    Publisher::Write(sr_writer_, sr.id, ++sr_seq_, sr.pose, frame);
    while (Clock::now() - t0 < 3s) {
      const auto arrival = watcher.FirstAfter(after_version, 3000ms);
      if (!arrival) break;
      grpc::ClientContext context;
      context.set_deadline(In(1000ms));
      v1::QueryPointsRequest request;
      *request.add_points() = P(kOnBoard);
      v1::QueryPointsResponse reply;
      if (client_->stub().QueryPoints(&context, request, &reply).ok() &&
          reply.map_version() >= arrival->first && reply.results_size() == 1 &&
          (!need_board || reply.results(0).state() != v1::VOXEL_STATE_UNKNOWN)) {
        return Ms(arrival->second - t0);
      }
      after_version = arrival->first;  // not this one: the next
    }
    return -1;
  }

  // 1a. First frame after ResetMap (every voxel of the frustum is new), worker idle.
  std::vector<double> LatenciesAfterReset(int* timeouts) {
    const SensorStream& sr = Sr();
    std::vector<double> after_reset_ms;
    for (int t = 0; t < std::max(3, options_.trials / 4); ++t) {
      const std::uint64_t reset_version = client_->Reset();
      VersionWatcher watcher(client_->stub(), reset_version);
      std::this_thread::sleep_for(250ms);
      const double ms =
          FrameToQueryableMs(watcher, reset_version, true, sr.frames[t % sr.frames.size()]);
      if (ms < 0)
        ++*timeouts;
      else
        after_reset_ms.push_back(ms);
    }
    return after_reset_ms;
  }

  // Maps the board with both sensors (steady state for the rest of the benchmark) and waits
  // until the worker is idle; the map version then.
  std::uint64_t MapTheBoard() {
    const SensorStream& sr = Sr();
    const SensorStream& stoc = Stoc();
    for (int i = 0; i < 15; ++i) {
      Publisher::Write(sr_writer_, sr.id, ++sr_seq_, sr.pose, sr.frames[i % sr.frames.size()]);
      Publisher::Write(stoc_writer_, stoc.id, ++stoc_seq_, stoc.pose,
                       stoc.frames[i % stoc.frames.size()]);
      std::this_thread::sleep_for(33ms);
    }
    std::uint64_t version = 0;
    for (int i = 0; i < 50; ++i) {  // until the worker is idle: no new version for 600 ms
      std::this_thread::sleep_for(600ms);
      const std::uint64_t v = CurrentVersion();
      if (v == version) break;
      version = v;
    }
    return version;
  }

  // 1b. Steady state: one more frame of the same stationary sensor into a mapped scene. The
  // gap after the previous render spreads over 0..250 ms: frames with a gap shorter than the
  // render interval wait for the render cadence, the others are rendered as soon as they are
  // integrated.
  void LatenciesInMappedScene(std::uint64_t version, int* timeouts) {
    const SensorStream& sr = Sr();
    const int trials = options_.trials;
    std::vector<double> all_ms, idle_ms, cadence_ms;
    const auto interval = std::chrono::milliseconds(render_interval_ms_);
    VersionWatcher watcher(client_->stub(), version);
    for (int t = 0; t < trials; ++t) {
      const auto gap = std::chrono::microseconds(250000 * t / std::max(1, trials - 1));
      std::this_thread::sleep_for(gap);
      const double ms =
          FrameToQueryableMs(watcher, version, false, sr.frames[t % sr.frames.size()]);
      if (ms < 0) {
        ++*timeouts;
        std::this_thread::sleep_for(1000ms);
      } else {
        all_ms.push_back(ms);
        (gap >= interval ? idle_ms : cadence_ms).push_back(ms);
      }
      version = CurrentVersion();
    }
    LatencyRow("mapped scene, all trials", all_ms);
    const std::string ms = std::to_string(render_interval_ms_) + " ms";
    LatencyRow(("mapped scene, gap < " + ms + " after previous render").c_str(), cadence_ms);
    LatencyRow(("mapped scene, gap >= " + ms + " (worker idle)").c_str(), idle_ms);
  }

  // One row of scenario 2: `clients` threads repeat the request for 1.5 s (at least 3 calls
  // each).
  void ThroughputRow(const v1::QueryPointsRequest& request, int batch, int clients) {
    std::vector<std::vector<double>> per_call_ms(static_cast<std::size_t>(clients));
    std::atomic<std::uint64_t> points{0};
    std::atomic<int> errors{0};
    const auto start = Clock::now();
    std::vector<std::thread> threads;
    for (int c = 0; c < clients; ++c) {
      threads.emplace_back([&, c] {
        while (Clock::now() - start < 1500ms || per_call_ms[c].size() < 3) {
          grpc::ClientContext context;
          context.set_deadline(In(10000ms));
          v1::QueryPointsResponse reply;
          const auto t0 = Clock::now();
          const auto status = client_->stub().QueryPoints(&context, request, &reply);
          if (!status.ok() || reply.results_size() != batch) {
            if (errors++ == 0)
              std::fprintf(stderr, "QueryPoints: %s\n", status.error_message().c_str());
            continue;
          }
          per_call_ms[c].push_back(Ms(Clock::now() - t0));
          points += static_cast<std::uint64_t>(batch);
        }
      });
    }
    for (auto& t : threads) t.join();
    const double elapsed_s = std::chrono::duration<double>(Clock::now() - start).count();
    std::vector<double> calls_ms;
    for (const auto& v : per_call_ms) calls_ms.insert(calls_ms.end(), v.begin(), v.end());
    std::printf("| %d | %d | %zu | %.1f | %.2fM |%s\n", batch, clients, calls_ms.size(),
                Percentile(calls_ms, 0.5), static_cast<double>(points) / elapsed_s / 1e6,
                errors > 0 ? " errors!" : "");
  }

  // Streams sr3000 and stoc at the given rates, each on a thread of its own, while `meanwhile`
  // runs; then stops them. What each publisher wrote, by sensor id.
  std::map<std::string, StreamStats> StreamWhile(double sr_hz, double stoc_hz,
                                                 const std::function<void()>& meanwhile) {
    std::atomic<bool> stop{false};
    StreamStats sr_stats, stoc_stats;  // one per thread
    std::thread sr_thread([&] { sr_stats = Stream(sr_writer_, Sr(), sr_hz, &sr_seq_, stop); });
    std::thread stoc_thread(
        [&] { stoc_stats = Stream(stoc_writer_, Stoc(), stoc_hz, &stoc_seq_, stop); });
    meanwhile();
    stop = true;
    sr_thread.join();
    stoc_thread.join();
    return {{"sr3000", sr_stats}, {"stoc", stoc_stats}};
  }

  const BenchOptions& options_;
  // The render interval fusiond runs with: the configuration's, or the service's default.
  unsigned render_interval_ms_ = service::DefaultConfig().map().render_interval_ms();
  const std::string dir_;
  const unsigned domain_;
  std::map<std::string, SensorStream> streams_;
  // Declared in the order they start, so that they stop in the reverse order.
  std::unique_ptr<FusiondProcess> fusiond_;
  std::unique_ptr<Client> client_;
  std::unique_ptr<Publisher> publisher_;
  dds_entity_t sr_writer_ = 0, stoc_writer_ = 0;
  std::uint64_t sr_seq_ = 0, stoc_seq_ = 0;  // the last sequence number each writer used
  // Scenarios 3 and 4 refill them (a failed ListSensors leaves the previous values).
  std::map<std::string, v1::SensorCounters> before_, after_;
};

// Scenarios 1 to 4 on one fusiond, those that --only names; 0, or the exit code.
inline int RunPaperScenarios(const BenchOptions& options, const std::string& dir, unsigned domain) {
  PaperScenarios scenarios(options, dir, domain);
  if (const int code = scenarios.Start(); code != 0) return code;
  if (options.Runs('1')) scenarios.LatencyOfOneFrame();
  if (options.Runs('2')) scenarios.QueryPointsThroughput();
  if (options.Runs('3')) scenarios.SmallQueriesWhileStreaming();
  if (options.Runs('4')) scenarios.DropsAt30And15Hz();
  const int code = scenarios.Stop();
  std::printf("fusiond (scenarios 1-4) exit code %d\n\n", code);
  return 0;
}

}  // namespace fusion::service_bench
