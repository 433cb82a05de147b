// TUM RGB-D fr2/pioneer_slam2 (10 Kinect frames, every pixel) mapped three ways, side by side:
//   1. through the service: fusion-import tum --stride 1 -> fusion-replay --fast --reliable ->
//      a fusiond process (127.0.0.1:0, private DDS domain, loopback DDS) with an explicit Kinect
//      sensor of one beam per pixel (640 x 480); timed from the replay's start until GetStats
//      clouds_in_map reaches the 10 clouds;
//   2. in process: the same recording fed to fusion::WorldMap (Integrate + Render per cloud),
//      with the sensor spec and map options converted from the same configuration file by the
//      service's own conversions;
//   3. OctoMap: octomap::OcTree::insertPointCloud of the same points (world frame, sensor
//      origin, max range = the Kinect's r_max).
// The import is timed separately. Prints a markdown table.
// Usage: tum_map_bench [--data DIR] [--resolution M] [--beams COLSxROWS] [--log-level LEVEL]
//                      [--timeout S]
//   --data: the TUM folder (default <repo>/../shared/data/tum_fr2_pioneer_slam2); absent: exit 0
//   --resolution: map voxel edge in metres (default 0.02); --beams: the Kinect's beam grid
//   (default 640x480, one beam per pixel; 160x120 gives each beam a 4 x 4 block of pixels, every
//   pixel still a reading of its beam, as the deployment does for the stereo camera);
//   --log-level: fusiond's (default warn;
//   other levels write its whole log to /tmp/tum_map_bench_fusiond.log); --timeout: seconds to
//   wait for the service's map (default 900).
#include <google/protobuf/descriptor.h>
#include <grpcpp/grpcpp.h>
#include <octomap/OcTree.h>
#include <signal.h>
#include <stdlib.h>
#include <unistd.h>

#include <Eigen/Geometry>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <memory>
#include <optional>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "../../support/subprocess.h"
#include "fusion/core/world_map.h"
#include "fusion/service/config.h"
#include "fusion/service/conversions.h"
#include "fusion/v1/map_service.grpc.pb.h"
#include "fusion/v1/recording.pb.h"

namespace {

using Clock = std::chrono::steady_clock;
using namespace std::chrono_literals;
namespace fs = std::filesystem;
namespace v1 = fusion::v1;
using fusion::testing::Subprocess;

const std::string kBinaryDir = FUSION_BINARY_DIR;
const std::string kSensorId = "kinect";
constexpr double kPi = 3.14159265358979323846;
constexpr double kKinectRMaxM = 6.0;
constexpr double kBeamCellSizeM = 0.02;  // as in tests/integration/e2e_tum_test.cc

double SecondsSince(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}
double Megabytes(double bytes) { return bytes / (1024.0 * 1024.0); }

// CPU time (user + system) of this process so far.
double OwnCpuSeconds() {
  timespec t{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
  return static_cast<double>(t.tv_sec) + 1e-9 * static_cast<double>(t.tv_nsec);
}

// CPU time (user + system, all threads) of another process so far; NAN if unreadable.
double ProcessCpuSeconds(pid_t pid) {
  std::ifstream in("/proc/" + std::to_string(pid) + "/stat");
  std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const auto paren = text.rfind(')');
  if (paren == std::string::npos) return NAN;
  std::istringstream fields(text.substr(paren + 1));
  std::string field;
  double ticks = 0;
  for (int i = 0; i <= 12 && fields >> field; ++i) {
    if (i == 11 || i == 12) ticks += std::atof(field.c_str());  // utime, stime (fields 14, 15)
  }
  return ticks / static_cast<double>(sysconf(_SC_CLK_TCK));
}

// ---- options -------------------------------------------------------------------------------

struct Options {
  std::string data_dir;
  double resolution_m = 0.02;
  int cols = 640, rows = 480;
  std::string log_level = "warn";
  double timeout_s = 900.0;
};

// The repository root from this file's path (tests/bench/service/tum_map_bench.cc).
std::string DefaultDataDir() {
  const fs::path source(__FILE__);
  const fs::path root = source.is_absolute()
                            ? source.parent_path().parent_path().parent_path().parent_path()
                            : fs::current_path();
  return (root / ".." / "shared" / "data" / "tum_fr2_pioneer_slam2").lexically_normal().string();
}

constexpr const char* kUsage =
    "usage: tum_map_bench [--data DIR] [--resolution M] [--beams COLSxROWS] [--log-level LEVEL]\n"
    "                     [--timeout S]\n"
    "  --data        the TUM folder (default ../shared/data/tum_fr2_pioneer_slam2)\n"
    "  --resolution  map voxel edge, metres (default 0.02)\n"
    "  --beams       the Kinect's beam grid (default 640x480: one beam per pixel)\n"
    "  --log-level   fusiond's (default warn)\n"
    "  --timeout     seconds to wait for the service's map (default 900)\n";

bool ParseArgs(int argc, char** argv, Options* options) {
  options->data_dir = DefaultDataDir();
  for (int i = 1; i < argc; i += 2) {
    const std::string flag = argv[i];
    if (i + 1 >= argc) {
      std::fprintf(stderr, "%s needs a value\n%s", flag.c_str(), kUsage);
      return false;
    }
    const std::string value = argv[i + 1];
    if (flag == "--data") {
      options->data_dir = value;
    } else if (flag == "--resolution") {
      options->resolution_m = std::atof(value.c_str());
    } else if (flag == "--beams") {
      if (std::sscanf(value.c_str(), "%dx%d", &options->cols, &options->rows) != 2 ||
          options->cols < 1 || options->rows < 1 || options->cols > 640 || options->rows > 480) {
        std::fprintf(stderr, "--beams wants COLSxROWS within 640x480, e.g. 160x120\n");
        return false;
      }
    } else if (flag == "--log-level") {
      options->log_level = value;
    } else if (flag == "--timeout") {
      options->timeout_s = std::atof(value.c_str());
    } else {
      std::fprintf(stderr, "unknown flag %s\n", flag.c_str());
      return false;
    }
  }
  if (!(options->resolution_m >= 0.001 && options->resolution_m <= 10.0)) {
    std::fprintf(stderr, "--resolution must lie in [0.001, 10] m\n");
    return false;
  }
  return true;
}

std::string CommandLine(int argc, char** argv) {
  std::string line;
  for (int i = 0; i < argc; ++i) line += (i ? " " : "") + std::string(argv[i]);
  return line;
}

std::string LoadAverage() {
  std::ifstream in("/proc/loadavg");
  std::string a, b, c;
  in >> a >> b >> c;
  return a + " " + b + " " + c;
}

// ---- configuration (the same file for fusiond and the in-process map) ----------------------

// The Kinect of e2e_tum_test.cc with cols x rows beams: the FOV covers every pixel (principal
// point off centre), sigma(r) = 0.0012 + 0.0019 (r - 0.4)^2 m.
std::string ConfigText(const Options& options) {
  const double resolution_m = options.resolution_m;
  const double fov_h_deg = 2.0 * std::atan(325.1 / 520.9) * 180.0 / kPi + 0.5;
  const double fov_v_deg = 2.0 * std::atan(249.7 / 521.0) * 180.0 / kPi + 0.5;
  const double s2 = 0.0019, s1 = -2.0 * 0.0019 * 0.4, s0 = 0.0012 + 0.0019 * 0.16;
  std::ostringstream config;
  config << "sensors { id: \"" << kSensorId << "\" model: \"paper3d\" r_min_m: 0.5 r_max_m: "
         << kKinectRMaxM << "\n"
         << "  fov_h_deg: " << fov_h_deg << " fov_v_deg: " << fov_v_deg << "\n"
         << "  cols: " << options.cols << " rows: " << options.rows << " epsilon: 0.02\n"
         << "  q_mu { a2: 0 a1: 1 a0: 0 }\n"
         << "  q_sigma { a2: " << s2 << " a1: " << s1 << " a0: " << s0 << " }\n"
         << "  queue_depth: 20 }\n"
         << "map { resolution_m: " << resolution_m
         << " render_interval_ms: 100 beam_cell_size_m: " << kBeamCellSizeM << " }\n"
         << "ingest { reliability: \"reliable\" }\n";
  return config.str();
}

// The sensor and map options fusiond derives from the file (FusionServer::Start does the same).
struct CoreSetup {
  fusion::service::SensorSetup sensor;
  fusion::WorldMapOptions map;
};

std::optional<CoreSetup> CoreSetupFromFile(const std::string& path) {
  v1::ServiceConfig config = fusion::service::DefaultConfig();
  std::string error;
  if (!fusion::service::LoadConfigFile(path, &config, &error) ||
      !fusion::service::ValidateConfig(config, &error)) {
    std::fprintf(stderr, "configuration: %s\n", error.c_str());
    return std::nullopt;
  }
  auto sensor = fusion::service::SensorSetupFromConfig(config.sensors(0), &error);
  auto map = fusion::service::WorldMapOptionsFromConfig(config.map(), &error);
  if (!sensor || !map) {
    std::fprintf(stderr, "configuration: %s\n", error.c_str());
    return std::nullopt;
  }
  return CoreSetup{*sensor, *map};
}

// ---- child processes -----------------------------------------------------------------------

// argv through a shell that joins stderr to stdout (which Subprocess reads).
std::vector<std::string> WithStderr(std::vector<std::string> argv) {
  argv.insert(argv.begin(), {"/bin/sh", "-c", "exec \"$0\" \"$@\" 2>&1"});
  return argv;
}

struct ToolRun {
  int exit_code = -1;
  double elapsed_s = 0;
  std::string output;
};

ToolRun RunTool(const std::vector<std::string>& argv, std::chrono::seconds timeout) {
  const auto t0 = Clock::now();
  Subprocess process(WithStderr(argv));
  ToolRun run;
  if (!process.started()) return run;
  (void)process.WaitForOutput("(?!)", timeout);  // drains until the child exits
  run.exit_code = process.Wait(5000ms);
  run.elapsed_s = SecondsSince(t0);
  run.output = process.output();
  return run;
}

// ---- the recording -------------------------------------------------------------------------

struct Frame {
  Eigen::Isometry3d T_world_sensor = Eigen::Isometry3d::Identity();
  std::vector<float> xyz;  // sensor frame, NaN = no return
  std::vector<std::uint8_t> beyond_range;
  std::uint32_t width = 0, height = 0;
};

Eigen::Isometry3d PoseOf(const v1::RecordedPose& p) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = Eigen::Quaterniond(p.qw(), p.qx(), p.qy(), p.qz()).normalized().toRotationMatrix();
  T.translation() = Eigen::Vector3d(p.tx(), p.ty(), p.tz());
  return T;
}

Frame FrameOf(const v1::RecordedCloud& cloud) {
  Frame frame;
  frame.T_world_sensor = PoseOf(cloud.t_world_sensor());
  frame.xyz.resize(cloud.xyz_f32le().size() / sizeof(float));
  std::memcpy(frame.xyz.data(), cloud.xyz_f32le().data(), frame.xyz.size() * sizeof(float));
  frame.beyond_range.assign(cloud.beyond_range().begin(), cloud.beyond_range().end());
  frame.width = cloud.width();
  frame.height = cloud.height();
  return frame;
}

// The clouds of a .frec file (docs/recording-format.md), frame by frame (CRCs not checked:
// fusion-replay checks them).
std::vector<Frame> ReadFrames(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::vector<Frame> frames;
  for (;;) {
    std::uint32_t head[2];
    if (!in.read(reinterpret_cast<char*>(head), sizeof head)) break;
    std::string payload(head[0], '\0');
    if (!in.read(payload.data(), head[0])) break;
    v1::RecordingFrame record;
    if (!record.ParseFromString(payload)) break;
    if (record.has_cloud()) frames.push_back(FrameOf(record.cloud()));
    if (record.has_index()) break;
  }
  return frames;
}

std::size_t FinitePoints(const Frame& frame) {
  std::size_t n = 0;
  for (std::size_t i = 0; i + 2 < frame.xyz.size(); i += 3) {
    n += std::isfinite(frame.xyz[i]) && std::isfinite(frame.xyz[i + 1]) &&
         std::isfinite(frame.xyz[i + 2]);
  }
  return n;
}

// ---- results -------------------------------------------------------------------------------

struct Row {
  std::string method;
  double time_s = NAN;
  std::uint64_t leaves = 0;
  double memory_bytes = 0;
  double cpu_s = NAN;  // CPU time of the process(es) doing the work, all threads
};

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
    stub_ = v1::FusionMap::NewStub(
        grpc::CreateChannel(address_, grpc::InsecureChannelCredentials()));
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
bool ServiceSettled(const v1::Stats& s, std::uint64_t clouds) {
  if (s.clouds_in_map() >= clouds) return true;
  const std::uint64_t decided = s.clouds_integrated() + s.clouds_rejected() + s.clouds_dropped();
  return decided >= clouds && s.clouds_in_map() == s.clouds_integrated();
}

struct ServiceTimes {
  double to_map_s = NAN;         // replay process start -> clouds_in_map == clouds
  double from_publish_s = NAN;   // replay's "publishing" line -> clouds_in_map == clouds
  double replay_exit_s = NAN;    // replay process start -> its exit
  double fusiond_cpu_s = NAN;    // fusiond's CPU time from the replay's start to the map
  int replay_exit_code = -1;
  std::string replay_output;
  v1::Stats stats;
};

// Polls GetStats every 20 ms until the map settles or the timeout passes.
std::optional<v1::Stats> WaitForMap(Fusiond& fusiond, std::uint64_t clouds, double timeout_s) {
  const auto t0 = Clock::now();
  while (SecondsSince(t0) < timeout_s) {
    const auto stats = fusiond.Stats();
    if (stats && ServiceSettled(*stats, clouds)) return stats;
    std::this_thread::sleep_for(20ms);
  }
  return std::nullopt;
}

ServiceTimes ReplayIntoService(Fusiond& fusiond, const std::string& recording, unsigned domain,
                               std::uint64_t clouds, double timeout_s) {
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
std::optional<std::uint64_t> CounterField(const v1::SensorCounters& c, const std::string& name) {
  const auto* field = c.GetDescriptor()->FindFieldByName(name);
  if (field == nullptr || field->cpp_type() != google::protobuf::FieldDescriptor::CPPTYPE_UINT64 ||
      field->is_repeated()) {
    return std::nullopt;
  }
  return c.GetReflection()->GetUInt64(c, field);
}

void PrintServiceCounters(const v1::SensorInfo& sensor, const v1::Stats& stats) {
  const auto& c = sensor.counters();
  const auto merged = CounterField(c, "merged");
  std::printf(
      "service counters (ListSensors '%s', %u x %u beams, sensor memory %.1f MB): received %llu, "
      "rejected %llu, dropped %llu, integrated %llu, merged %s, points_updated %llu, "
      "points_beyond_range %llu, points_missing %llu, points_rejected %llu\n",
      sensor.id().c_str(), sensor.cols(), sensor.rows(), Megabytes(sensor.memory_bytes()),
      (unsigned long long)c.received(), (unsigned long long)c.rejected(),
      (unsigned long long)c.dropped(), (unsigned long long)c.integrated(),
      merged ? std::to_string(*merged).c_str() : "(no such counter)",
      (unsigned long long)c.points_updated(), (unsigned long long)c.points_beyond_range(),
      (unsigned long long)c.points_missing(), (unsigned long long)c.points_rejected());
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
void PrintFusiondProblems(const std::string& output) {
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
void SaveLog(const std::string& output) {
  const std::string path = "/tmp/tum_map_bench_fusiond.log";
  std::ofstream(path) << output;
  std::printf("fusiond output written to %s\n", path.c_str());
}

std::optional<Row> RunService(const std::string& config_path, const std::string& recording,
                              std::uint64_t clouds, const Options& options) {
  const unsigned domain = fusion::testing::PrivateDomainId();
  Fusiond fusiond(config_path, domain, options.log_level);
  if (!fusiond.ok()) {
    std::fprintf(stderr, "fusiond did not start: %s\n", fusiond.output().c_str());
    return std::nullopt;
  }
  std::printf("fusiond: %s/service/fusiond --config %s --listen 127.0.0.1:0 --dds-domain %u "
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
    std::printf("service: clouds_in_map %llu of %llu after %.2f s from the replay's start "
                "(%.2f s after its 'publishing' line, i.e. without DDS discovery); fusiond CPU "
                "time meanwhile %.2f s (its integrator and renderer threads run at nice 10)\n",
                (unsigned long long)times.stats.clouds_in_map(), (unsigned long long)clouds,
                times.to_map_s, times.from_publish_s, times.fusiond_cpu_s);
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

// ---- 2. ours in process --------------------------------------------------------------------

struct CoreTotals {
  fusion::IntegrationStats integration;
  std::size_t failures = 0;
  double integrate_s = 0;
  double render_s = 0;
};

void AddStats(const fusion::IntegrationStats& s, fusion::IntegrationStats* total) {
  total->updated += s.updated;
  total->beyond_range += s.beyond_range;
  total->missing += s.missing;
  total->rejected_nonfinite += s.rejected_nonfinite;
  total->rejected_outside_fov += s.rejected_outside_fov;
}

void IntegrateAndRender(fusion::WorldMap& map, const CoreSetup& setup, const Frame& frame,
                        CoreTotals* totals) {
  fusion::IntegrationStats stats;
  const Eigen::Isometry3d T = frame.T_world_sensor * setup.sensor.T_published_sensor;
  const auto t0 = Clock::now();
  const auto integrated = map.Integrate(kSensorId, T, frame.xyz.data(), frame.xyz.size() / 3,
                                        frame.beyond_range, &stats);
  totals->integrate_s += SecondsSince(t0);
  AddStats(stats, &totals->integration);
  if (integrated != fusion::MapStatus::kOk) {
    std::printf("  in process: Integrate: %s\n", fusion::MapStatusName(integrated));
    ++totals->failures;
    return;
  }
  const auto t1 = Clock::now();
  const auto rendered = map.Render(kSensorId);
  totals->render_s += SecondsSince(t1);
  if (rendered != fusion::MapStatus::kOk) {
    std::printf("  in process: Render: %s\n", fusion::MapStatusName(rendered));
    ++totals->failures;
  }
}

void PrintCoreCounters(const fusion::WorldMap& map, const CoreTotals& totals) {
  const auto& s = totals.integration;
  std::printf(
      "in-process counters: points updated %zu, beyond range %zu, missing %zu, rejected "
      "non-finite %zu, rejected outside the FOV %zu; failures %zu; Integrate (incl. committing "
      "the previous period when the pose moved) %.2f s, Render %.2f s\n",
      s.updated, s.beyond_range, s.missing, s.rejected_nonfinite, s.rejected_outside_fov,
      totals.failures, totals.integrate_s, totals.render_s);
  if (const auto c = map.Counters(kSensorId)) {
    std::printf("  WorldMap counters: frames integrated %llu, renders %llu, commits %llu, "
                "pose moves %llu\n",
                (unsigned long long)c->frames_integrated, (unsigned long long)c->renders,
                (unsigned long long)c->commits, (unsigned long long)c->pose_moves);
  }
  std::printf("  WorldMap::MemoryBytes (history + working + published trees + live): %.1f MB\n",
              Megabytes(static_cast<double>(map.MemoryBytes())));
}

std::optional<Row> RunCore(const CoreSetup& setup, const std::vector<Frame>& frames) {
  std::printf("in process: WorldMap resolution %.3f m, beam cell %.3f m, render threads %u, "
              "rule %d, %d x %d beams\n",
              setup.map.resolution_m, setup.map.beam_grid.cell_size_m, setup.map.render.threads,
              static_cast<int>(setup.map.rule), setup.sensor.spec.cols, setup.sensor.spec.rows);
  fusion::WorldMap map(setup.map);
  if (map.AddSensor(kSensorId, setup.sensor.spec) != fusion::MapStatus::kOk) {
    std::fprintf(stderr, "in process: AddSensor failed\n");
    return std::nullopt;
  }
  CoreTotals totals;
  const double cpu0_s = OwnCpuSeconds();
  const auto t0 = Clock::now();
  for (const auto& frame : frames) IntegrateAndRender(map, setup, frame, &totals);
  const double elapsed_s = SecondsSince(t0);
  const double cpu_s = OwnCpuSeconds() - cpu0_s;
  PrintCoreCounters(map, totals);
  const auto& tree = map.tree();
  return Row{"ours, in process (WorldMap Integrate + Render per cloud)", elapsed_s,
             tree.getNumLeafNodes(), static_cast<double>(tree.memoryUsage()), cpu_s};
}

// ---- 3. OctoMap ----------------------------------------------------------------------------

octomap::Pointcloud WorldCloud(const Frame& frame) {
  octomap::Pointcloud cloud;
  cloud.reserve(frame.xyz.size() / 3);
  for (std::size_t i = 0; i + 2 < frame.xyz.size(); i += 3) {
    const Eigen::Vector3d p(frame.xyz[i], frame.xyz[i + 1], frame.xyz[i + 2]);
    if (!p.allFinite()) continue;
    const Eigen::Vector3d w = frame.T_world_sensor * p;
    cloud.push_back(static_cast<float>(w.x()), static_cast<float>(w.y()),
                    static_cast<float>(w.z()));
  }
  return cloud;
}

// The world-frame clouds are built before the clock starts; only insertPointCloud is timed.
Row RunOctomap(const std::vector<Frame>& frames, double resolution_m) {
  std::vector<octomap::Pointcloud> clouds;
  std::vector<octomap::point3d> origins;
  for (const auto& frame : frames) {
    clouds.push_back(WorldCloud(frame));
    const Eigen::Vector3d o = frame.T_world_sensor.translation();
    origins.emplace_back(static_cast<float>(o.x()), static_cast<float>(o.y()),
                         static_cast<float>(o.z()));
  }
  octomap::OcTree tree(resolution_m);
  const double cpu0_s = OwnCpuSeconds();
  const auto t0 = Clock::now();
  for (std::size_t i = 0; i < clouds.size(); ++i)
    tree.insertPointCloud(clouds[i], origins[i], kKinectRMaxM);
  const double elapsed_s = SecondsSince(t0);
  const double cpu_s = OwnCpuSeconds() - cpu0_s;
  std::printf("OctoMap: insertPointCloud (max range %.1f m, default sensor model, pruned as it "
              "goes), %zu nodes\n",
              kKinectRMaxM, tree.size());
  return Row{"OctoMap insertPointCloud", elapsed_s, tree.getNumLeafNodes(),
             static_cast<double>(tree.memoryUsage()), cpu_s};
}

// ---- report --------------------------------------------------------------------------------

void PrintTable(const std::vector<Row>& rows, const std::optional<Row>& octomap) {
  std::printf("\n| method | time [s] | leaves | memory [MB] | OctoMap time / this time | "
              "CPU [s] |\n|---|---|---|---|---|---|\n");
  for (const auto& row : rows) {
    char ratio[32] = "-";
    if (octomap && row.method != octomap->method)
      std::snprintf(ratio, sizeof ratio, "%.2fx", octomap->time_s / row.time_s);
    std::printf("| %s | %.2f | %llu | %.1f | %s | %.2f |\n", row.method.c_str(), row.time_s,
                (unsigned long long)row.leaves, Megabytes(row.memory_bytes), ratio, row.cpu_s);
  }
  std::printf(
      "\ntime: wall clock. fusiond: from starting fusion-replay to GetStats clouds_in_map == all "
      "clouds (DDS discovery, transfer, integration, rendering, publication); in process: the "
      "Integrate + Render loop; OctoMap: the insertPointCloud loop (world-frame clouds built "
      "before). leaves / memory: getNumLeafNodes / memoryUsage of the (published) octree. CPU: "
      "fusiond's process (all threads) / this process during the same interval.\n");
}

std::optional<ToolRun> Import(const std::string& data_dir, const std::string& recording) {
  const ToolRun run = RunTool({kBinaryDir + "/clients/fusion-import", "tum", data_dir, "--stride",
                               "1", "--sensor-id", kSensorId, "-o", recording},
                              std::chrono::seconds(300));
  std::printf("import: fusion-import tum %s --stride 1 --sensor-id %s -o %s: exit %d, %.2f s\n%s",
              data_dir.c_str(), kSensorId.c_str(), recording.c_str(), run.exit_code,
              run.elapsed_s, run.output.c_str());
  if (run.exit_code != 0) return std::nullopt;
  return run;
}

void PrintFrames(const std::vector<Frame>& frames, const std::string& recording) {
  std::size_t points = 0, finite = 0;
  for (const auto& f : frames) {
    points += f.xyz.size() / 3;
    finite += FinitePoints(f);
  }
  std::printf("recording %s: %.1f MB, %zu clouds of %u x %u, %zu pixels, %zu with a depth "
              "(finite points)\n",
              recording.c_str(), Megabytes(static_cast<double>(fs::file_size(recording))),
              frames.size(), frames.empty() ? 0 : frames[0].width,
              frames.empty() ? 0 : frames[0].height, points, finite);
}

bool ToolsPresent() {
  for (const char* tool : {"/service/fusiond", "/clients/fusion-import", "/clients/fusion-replay"}) {
    if (!fs::exists(kBinaryDir + tool)) {
      std::fprintf(stderr, "%s%s is missing: build it first\n", kBinaryDir.c_str(), tool);
      return false;
    }
  }
  return true;
}

int RunAll(const Options& options, const std::string& dir) {
  const std::string recording = dir + "/tum_stride1.frec";
  const auto import = Import(options.data_dir, recording);
  if (!import) return 1;
  const std::vector<Frame> frames = ReadFrames(recording);
  PrintFrames(frames, recording);
  if (frames.empty()) return 1;
  const std::string config_path = dir + "/fusiond.pbtxt";
  std::ofstream(config_path) << ConfigText(options);
  std::printf("configuration (fusiond and in process):\n\n```\n%s```\n\n",
              ConfigText(options).c_str());
  const auto setup = CoreSetupFromFile(config_path);
  if (!setup) return 1;

  std::printf("\n## 1. ours through the service\n\n");
  const auto service = RunService(config_path, recording, frames.size(), options);
  std::printf("\n## 2. ours in process\n\n");
  const auto core = RunCore(*setup, frames);
  std::printf("\n## 3. OctoMap\n\n");
  const Row octomap = RunOctomap(frames, options.resolution_m);

  std::vector<Row> rows;
  if (service) rows.push_back(*service);
  if (core) rows.push_back(*core);
  rows.push_back(octomap);
  std::printf("\n## Results at %.3f m, %d x %d beams (import, not compared: %.2f s)\n",
              options.resolution_m, options.cols, options.rows, import->elapsed_s);
  PrintTable(rows, octomap);
  if (!service) std::printf("\n(the service row is missing: see section 1)\n");
  return service && core ? 0 : 1;
}

}  // namespace

int main(int argc, char** argv) {
  Options options;
  if (argc == 2 && std::string(argv[1]) == "--help") {
    std::printf("%s", kUsage);
    return 0;
  }
  if (!ParseArgs(argc, argv, &options)) return 2;
  std::printf("# TUM fr2/pioneer_slam2, every pixel: fusiond vs. WorldMap vs. OctoMap\n\n"
              "command: %s\n\nload average at start: %s; hardware threads: %u\n\n",
              CommandLine(argc, argv).c_str(), LoadAverage().c_str(),
              std::thread::hardware_concurrency());
  if (!fs::exists(fs::path(options.data_dir) / "groundtruth.txt")) {
    std::printf("TUM data missing: %s (see ../shared/data/README.md: tum_fr2_pioneer_slam2); "
                "give --data DIR. Nothing measured.\n",
                options.data_dir.c_str());
    return 0;
  }
  if (!ToolsPresent()) return 1;
  char dir_template[] = "/tmp/tum_map_bench_XXXXXX";
  const char* dir = mkdtemp(dir_template);
  if (dir == nullptr) return 1;
  const auto t0 = Clock::now();
  const int code = RunAll(options, dir);
  std::printf("\ntotal %.1f s; load average at end: %s\n", SecondsSince(t0),
              LoadAverage().c_str());
  fs::remove_all(dir);
  return code;
}
