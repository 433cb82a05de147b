// soak: fusiond under sustained load for minutes (issue 14, item 6). Two simulated sensors
// stream over DDS, query clients loop over every RPC, update subscribers come and go; the
// report gives errors by RPC and code, latency per RPC, the clouds' fate and fusiond's RSS
// over time. `soak --help` for the flags; docs/service.md ("Soak") for how to run it.
#include <signal.h>
#include <stdlib.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <ctime>
#include <map>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "../../support/subprocess.h"
#include "soak_clients.h"
#include "soak_fusiond.h"
#include "soak_options.h"
#include "soak_recorder.h"
#include "soak_report.h"
#include "soak_sensors.h"
#include "soak_streams.h"

namespace {

using namespace fusion::soak;
using namespace std::chrono_literals;
namespace v1 = fusion::v1;

const std::string kFusiond = std::string(FUSION_BINARY_DIR) + "/service/fusiond";
const std::string kDeploymentConfig = std::string(FUSION_SOURCE_DIR) + "/docker/fusiond.pbtxt";

std::atomic<bool> g_stop{false};
void OnSignal(int) { g_stop = true; }

double Seconds(SoakClock::duration d) { return std::chrono::duration<double>(d).count(); }

std::string UtcNow() {
  const std::time_t now = std::time(nullptr);
  char text[32];
  std::strftime(text, sizeof text, "%Y-%m-%d %H:%M UTC", std::gmtime(&now));
  return text;
}

std::string CommandLine(int argc, char** argv) {
  std::string line = "build/tests/soak";
  for (int i = 1; i < argc; ++i) line += std::string(" ") + argv[i];
  return line;
}

// The service under test: a child of this process, or one it attached to.
struct Target {
  std::unique_ptr<FusiondChild> child;
  std::string address;
  unsigned domain = 0;
  long pid = -1;  // whose RSS is sampled; -1: none
};

bool StartOwn(const Options& o, const std::string& dir, Target* t, RunResult* r) {
  t->domain = fusion::testing::PrivateDomainId();
  const std::string config = o.config.empty() ? kDeploymentConfig : o.config;
  t->child = std::make_unique<FusiondChild>(
      o.fusiond.empty() ? kFusiond : o.fusiond,
      std::vector<std::string>{"--config", config, "--listen", "127.0.0.1:0", "--dds-domain",
                               std::to_string(t->domain), "--snapshot", dir + "/map.ot",
                               "--log-level", o.log_level},
      dir + "/fusiond.log");
  if (!t->child->WaitServing()) {
    std::fprintf(stderr, "soak: fusiond did not start; see %s/fusiond.log\n", dir.c_str());
    return false;
  }
  t->address = t->child->address();
  t->pid = t->child->pid();
  r->fusiond_command = t->child->command();
  return true;
}

void Attach(const Options& o, Target* t, RunResult* r) {
  t->address = o.target;
  t->domain = static_cast<unsigned>(o.domain);
  t->pid = o.fusiond_pid;
  r->own_fusiond = false;
  r->fusiond_command = "attached to " + o.target;
}

// GetStats and ListSensors for the progress lines and the counters (not part of the mix).
class Monitor {
 public:
  explicit Monitor(const std::string& address)
      : stub_(v1::FusionMap::NewStub(NewChannel(address))) {}
  bool Poll(v1::Stats* stats, std::map<std::string, v1::SensorInfo>* sensors) {
    grpc::ClientContext a, b;
    a.set_deadline(std::chrono::system_clock::now() + 5s);
    b.set_deadline(std::chrono::system_clock::now() + 5s);
    v1::ListSensorsResponse reply;
    if (!stub_->GetStats(&a, v1::GetStatsRequest(), stats).ok() ||
        !stub_->ListSensors(&b, v1::ListSensorsRequest(), &reply).ok())
      return false;
    sensors->clear();
    for (const auto& s : reply.sensors()) (*sensors)[s.id()] = s;
    return true;
  }

 private:
  std::unique_ptr<v1::FusionMap::Stub> stub_;
};

// The soak's sensor ids with their beam counts, if the target configures both.
bool SensorsOf(Monitor& monitor, const Options& o, ClientSetup* setup) {
  v1::Stats stats;
  std::map<std::string, v1::SensorInfo> sensors;
  if (!monitor.Poll(&stats, &sensors)) {
    std::fprintf(stderr, "soak: GetStats / ListSensors failed on the target\n");
    return false;
  }
  for (const std::string& id : {o.sr_id, o.stoc_id}) {
    if (sensors.count(id) == 0) {
      std::fprintf(stderr, "soak: the target has no sensor '%s' (see --sr-id, --stoc-id)\n",
                   id.c_str());
      return false;
    }
    setup->sensors.emplace_back(id, sensors.at(id).beams());
  }
  return true;
}

// Everything that loads the service, started and stopped together.
class Load {
 public:
  Load(const Options& o, const ClientSetup& setup, Recorder* recorder) {
    for (std::uint64_t i = 0; i < o.clients; ++i)
      clients_.push_back(std::make_unique<QueryClient>(setup, recorder, o.seed * 1000 + i));
    for (std::uint64_t i = 0; i < o.subscribers; ++i)
      subscribers_.push_back(std::make_unique<UpdateSubscriber>(
          setup.address, o.stay_min_s, o.stay_max_s, recorder, &streams, o.seed * 1000 + 500 + i));
  }
  void Start() {
    for (auto& c : clients_) threads_.emplace_back([this, &c] { c->Run(stop_); });
    for (auto& s : subscribers_) threads_.emplace_back([this, &s] { s->Run(stop_); });
  }
  void Stop() {
    stop_ = true;
    for (auto& s : subscribers_) s->Cancel();
    for (auto& t : threads_) t.join();
    threads_.clear();
  }
  StreamTotals streams;

 private:
  std::atomic<bool> stop_{false};
  std::vector<std::unique_ptr<QueryClient>> clients_;
  std::vector<std::unique_ptr<UpdateSubscriber>> subscribers_;
  std::vector<std::thread> threads_;
};

struct Counters {
  v1::Stats stats;
  std::map<std::string, v1::SensorInfo> sensors;
};

std::uint64_t Sum(const std::map<std::string, v1::SensorInfo>& sensors,
                  std::uint64_t (v1::SensorCounters::*field)() const) {
  std::uint64_t n = 0;
  for (const auto& [id, s] : sensors) n += (s.counters().*field)();
  return n;
}

void PrintProgress(double t_s, const Recorder& recorder, const Counters& now, const Counters& start,
                   std::uint64_t published, double rss_mb) {
  using C = v1::SensorCounters;
  const auto totals = recorder.Sum();
  const auto delta = [&](std::uint64_t (C::*f)() const) {
    return static_cast<unsigned long long>(Sum(now.sensors, f) - Sum(start.sensors, f));
  };
  std::printf(
      "[%4.0f s] calls %llu (%.0f/s), shed %llu, errors %llu | clouds published %llu, "
      "received %llu, dropped %llu, integrated %llu, merged %llu | map v%llu, %llu leaves | "
      "fusiond RSS %.1f MB | load %s\n",
      t_s, static_cast<unsigned long long>(totals.calls),
      t_s >= 1 ? static_cast<double>(totals.calls) / t_s : 0.0,
      static_cast<unsigned long long>(totals.shed), static_cast<unsigned long long>(totals.errors),
      static_cast<unsigned long long>(published), delta(&C::received), delta(&C::dropped),
      delta(&C::integrated), delta(&C::merged),
      static_cast<unsigned long long>(now.stats.map_version()),
      static_cast<unsigned long long>(now.stats.map_leaves()), rss_mb, LoadAverage().c_str());
  std::fflush(stdout);
}

std::uint64_t Published(const std::vector<std::unique_ptr<SensorPublisher>>& publishers) {
  std::uint64_t n = 0;
  for (const auto& p : publishers) n += p->written;
  return n;
}

// Sleeps until `until` or a signal.
void SleepUntil(SoakClock::time_point until) {
  while (!g_stop && SoakClock::now() < until) std::this_thread::sleep_for(50ms);
}

// The run's clock: a progress line and an RSS sample every 10 s until the duration ends, a
// signal comes or fusiond goes away.
void RunFor(const Options& o, Target& target, Monitor& monitor, const Recorder& recorder,
            const Counters& start_counters,
            const std::vector<std::unique_ptr<SensorPublisher>>& publishers, RunResult* r) {
  const auto start = SoakClock::now();
  const double fusiond_cpu0_s = target.pid > 0 ? ProcCpuS(target.pid) : -1;
  const double soak_cpu0_s = OwnCpuS();
  r->load_average_start = LoadAverage();
  const auto end = start + std::chrono::duration_cast<SoakClock::duration>(
                               std::chrono::duration<double>(o.duration_s));
  for (int tick = 0;; ++tick) {
    const double t_s = Seconds(SoakClock::now() - start);
    const double rss_mb = target.pid > 0 ? ProcStatusMb(target.pid, "VmRSS") : -1;
    if (rss_mb >= 0) r->rss.push_back({t_s, rss_mb});
    Counters now;
    if (monitor.Poll(&now.stats, &now.sensors)) {
      PrintProgress(t_s, recorder, now, start_counters, Published(publishers), rss_mb);
    } else {
      ++r->monitor_failures;
      std::printf("[%4.0f s] GetStats / ListSensors failed\n", t_s);
    }
    if (target.child && !target.child->Running()) r->fusiond_died = true;
    if (g_stop || r->fusiond_died || SoakClock::now() >= end) break;
    SleepUntil(std::min(end, start + (tick + 1) * 10s));
  }
  r->load_s = Seconds(SoakClock::now() - start);
  r->soak_cpu_s = OwnCpuS() - soak_cpu0_s;
  r->load_average_end = LoadAverage();
  if (fusiond_cpu0_s >= 0 && ProcCpuS(target.pid) >= 0)
    r->fusiond_cpu_s = ProcCpuS(target.pid) - fusiond_cpu0_s;
}

// After the publishers stop: waits (up to 15 s) until every received cloud was dropped,
// rejected or integrated.
Counters Drain(Monitor& monitor) {
  using C = v1::SensorCounters;
  Counters c;
  const auto until = SoakClock::now() + 15s;
  std::this_thread::sleep_for(500ms);  // the last clouds on their way
  while (SoakClock::now() < until) {
    std::this_thread::sleep_for(500ms);
    if (!monitor.Poll(&c.stats, &c.sensors)) continue;
    if (Sum(c.sensors, &C::received) <=
        Sum(c.sensors, &C::dropped) + Sum(c.sensors, &C::rejected) + Sum(c.sensors, &C::integrated))
      break;
  }
  return c;
}

void CollectSensors(const std::vector<std::unique_ptr<SensorPublisher>>& publishers,
                    const Counters& before, const Counters& after, RunResult* r) {
  for (const auto& p : publishers) {
    SensorResult s;
    s.id = p->id();
    s.points_per_frame = p->points_per_frame();
    s.published = p->written;
    s.write_failures = p->write_failures;
    s.late_ticks = p->late_ticks;
    if (before.sensors.count(s.id)) s.before = before.sensors.at(s.id).counters();
    if (after.sensors.count(s.id)) s.after = after.sensors.at(s.id).counters();
    r->sensors.push_back(s);
  }
}

void PrintSetup(const Options& o, const Target& t, const RunResult& r, const SensorLaps& laps) {
  const char* uri = std::getenv("CYCLONEDDS_URI");
  std::printf(
      "# fusiond soak\n\n%s\n\ncommand: `%s`\nfusiond: `%s` (gRPC %s, DDS domain %u, DDS "
      "configuration: %s)\nrun folder: %s\nload: %llu clients (think %.0f ms), %llu "
      "subscribers (stay %.0f-%.0f s), SaveMap every %.0f s, ResetMap every %.0f s; sensors "
      "%s (%u x %u) and %s (%u x %u points) at %.0f Hz on a %.0f s lap; %.0f s\nmix (weights):",
      r.date.c_str(), r.command_line.c_str(), r.fusiond_command.c_str(), t.address.c_str(),
      t.domain, uri ? uri : "the embedded loopback one", r.run_dir.c_str(),
      static_cast<unsigned long long>(o.clients), o.think_ms,
      static_cast<unsigned long long>(o.subscribers), o.stay_min_s, o.stay_max_s, o.save_every_s,
      o.reset_every_s, o.sr_id.c_str(), laps.sr.front().width, laps.sr.front().height,
      o.stoc_id.c_str(), laps.stoc.front().width, laps.stoc.front().height, o.rate_hz, kLapS,
      o.duration_s);
  for (const auto& w : o.mix) std::printf(" %s %d", RpcName(w.rpc), w.weight);
  std::printf("\n\n");
  std::fflush(stdout);
}

// Starts the sensors, the load, runs, stops; fills *r. False if something could not start.
bool Soak(const Options& o, Target& target, RunResult* r) {
  Monitor monitor(target.address);
  ClientSetup setup{target.address, o.think_ms, o.mix, {}, nullptr, nullptr};
  if (!SensorsOf(monitor, o, &setup)) return false;
  const auto simulate_start = SoakClock::now();
  SensorLaps laps = SimulateLaps(o.sr_id, o.stoc_id, o.stoc_cols, o.stoc_rows, o.rate_hz);
  PrintSetup(o, target, *r, laps);
  std::printf("lap simulated in %.1f s\n\n", Seconds(SoakClock::now() - simulate_start));
  Counters before;
  if (!monitor.Poll(&before.stats, &before.sensors)) return false;
  std::vector<std::unique_ptr<SensorPublisher>> publishers;
  publishers.push_back(
      std::make_unique<SensorPublisher>(target.domain, std::move(laps.sr), o.rate_hz));
  publishers.push_back(
      std::make_unique<SensorPublisher>(target.domain, std::move(laps.stoc), o.rate_hz));
  for (auto& p : publishers) {
    if (!p->Start()) {
      std::fprintf(stderr, "soak: sensor %s: %s\n", p->id().c_str(), p->error().c_str());
      return false;
    }
  }
  Schedule save(o.save_every_s), reset(o.reset_every_s);
  setup.save = &save;
  setup.reset = &reset;
  Recorder recorder;
  Load load(o, setup, &recorder);
  load.Start();
  RunFor(o, target, monitor, recorder, before, publishers, r);
  load.Stop();
  for (auto& p : publishers) p->Stop();
  const Counters after = Drain(monitor);
  CollectSensors(publishers, before, after, r);
  r->stats_after = after.stats;
  r->records = recorder.Records();
  r->streams = {load.streams.sessions, load.streams.messages, load.streams.voxels,
                load.streams.full_messages, load.streams.silent_sessions};
  return true;
}

}  // namespace

int main(int argc, char** argv) {
  Options options;
  if (const int code = ParseOptions(argc, argv, &options); code != 0) return code < 0 ? 0 : code;
  std::signal(SIGINT, OnSignal);
  std::signal(SIGTERM, OnSignal);
  char dir_template[] = "/tmp/soak_XXXXXX";
  if (mkdtemp(dir_template) == nullptr) return 1;
  RunResult result;
  result.run_dir = dir_template;
  result.date = UtcNow();
  result.command_line = CommandLine(argc, argv);
  Target target;
  if (options.target.empty()) {
    if (!StartOwn(options, result.run_dir, &target, &result)) return 1;
  } else {
    Attach(options, &target, &result);
  }
  const bool ran = Soak(options, target, &result);
  if (target.child) {
    result.fusiond_exit_code = target.child->Stop();
    result.log = SummarizeLog(result.run_dir + "/fusiond.log");
    std::remove((result.run_dir + "/map.ot").c_str());  // the map is not kept, the log is
  }
  if (!ran) return 1;
  PrintReport(result);
  if (!options.json_path.empty() && !WriteJson(options.json_path, result)) {
    std::fprintf(stderr, "soak: cannot write %s\n", options.json_path.c_str());
    return 1;
  }
  return Failures(result).empty() ? 0 : 1;
}
