// tum_map_bench (tum_map_bench.cc): what the three ways of mapping share: clocks and CPU time,
// the command line, the one configuration file (fusiond's and the in-process map's), running
// the client tools, and a row of the results table.
#pragma once

#include <unistd.h>

#include <Eigen/Geometry>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include "../../support/subprocess.h"
#include "fusion/core/world_map.h"
#include "fusion/service/config.h"
#include "fusion/service/conversions.h"
#include "fusion/v1/config.pb.h"

namespace fusion::tum_map_bench {

using Clock = std::chrono::steady_clock;
using namespace std::chrono_literals;  // NOLINT: the bench's durations (20s, 5000ms)
namespace fs = std::filesystem;
namespace v1 = fusion::v1;
using fusion::testing::Subprocess;

inline const std::string kBinaryDir = FUSION_BINARY_DIR;
inline const std::string kSensorId = "kinect";
constexpr double kPi = 3.14159265358979323846;
constexpr double kKinectRMaxM = 6.0;
constexpr double kBeamCellSizeM = 0.02;  // as in tests/integration/e2e_tum_test.cc

inline double SecondsSince(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}
inline double Megabytes(double bytes) { return bytes / (1024.0 * 1024.0); }

// CPU time (user + system) of this process so far.
inline double OwnCpuSeconds() {
  timespec t{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
  return static_cast<double>(t.tv_sec) + 1e-9 * static_cast<double>(t.tv_nsec);
}

// CPU time (user + system, all threads) of another process so far; NAN if unreadable.
inline double ProcessCpuSeconds(pid_t pid) {
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
  // The map's pose tolerance: frames within it of a period's first pose join that period (its
  // beam grids, change detection); 0: the service's default (1 cm, 1 deg).
  double pose_tolerance_m = 0.0;
  double pose_tolerance_deg = 0.0;
  // map.render_threads; -1: not set (the service's default, one fewer than the hardware threads).
  int render_threads = -1;
  // The sensor's description: "hand" (the hand-typed Kinect of e2e_tum_test.cc on an angular
  // grid of cols x rows beams) or "kinect_v1" (the preset: one beam per pixel, the model
  // fusion-calibrate fitted on this recording).
  std::string model = "hand";
};

// The repository root from this file's path (tests/bench/service/tum_map_bench_common.h).
inline std::string DefaultDataDir() {
  const fs::path source(__FILE__);
  const fs::path root = source.is_absolute()
                            ? source.parent_path().parent_path().parent_path().parent_path()
                            : fs::current_path();
  return (root / ".." / "shared" / "data" / "tum_fr2_pioneer_slam2").lexically_normal().string();
}

constexpr const char* kUsage =
    "usage: tum_map_bench [--data DIR] [--resolution M] [--beams COLSxROWS] [--log-level LEVEL]\n"
    "                     [--timeout S] [--pose-tolerance M,DEG] [--render-threads N]\n"
    "                     [--model hand|kinect_v1]\n"
    "  --data        the TUM folder (default ../shared/data/tum_fr2_pioneer_slam2)\n"
    "  --resolution  map voxel edge, metres (default 0.02)\n"
    "  --beams       the Kinect's beam grid (default 640x480: one beam per pixel)\n"
    "  --log-level   fusiond's (default warn)\n"
    "  --timeout     seconds to wait for the service's map (default 900)\n"
    "  --pose-tolerance  frames within M metres and DEG degrees of a period's first pose join\n"
    "                it (default: the service's 0.01,1); wider ones let change detection judge\n"
    "                later frames against earlier ones\n"
    "  --render-threads  map.render_threads for fusiond and the in-process map (default: the\n"
    "                service's, one fewer than the hardware threads, at least 1)\n"
    "  --model       the sensor: hand (default; the hand-typed Kinect, sigma 6 mm at 2 m, eps\n"
    "                0.02, on the --beams grid) or kinect_v1 (the preset: pinhole, one beam per\n"
    "                pixel, the model fitted by fusion-calibrate; --beams does not apply)\n";

inline bool ParseArgs(int argc, char** argv, Options* options) {
  options->data_dir = DefaultDataDir();
  bool beams_given = false;
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
      beams_given = true;
      if (std::sscanf(value.c_str(), "%dx%d", &options->cols, &options->rows) != 2 ||
          options->cols < 1 || options->rows < 1 || options->cols > 640 || options->rows > 480) {
        std::fprintf(stderr, "--beams wants COLSxROWS within 640x480, e.g. 160x120\n");
        return false;
      }
    } else if (flag == "--model") {
      if (value != "hand" && value != "kinect_v1") {
        std::fprintf(stderr, "--model wants hand or kinect_v1\n");
        return false;
      }
      options->model = value;
    } else if (flag == "--log-level") {
      options->log_level = value;
    } else if (flag == "--timeout") {
      options->timeout_s = std::atof(value.c_str());
    } else if (flag == "--pose-tolerance") {
      if (std::sscanf(value.c_str(), "%lf,%lf", &options->pose_tolerance_m,
                      &options->pose_tolerance_deg) != 2 ||
          !(options->pose_tolerance_m > 0.0) || !(options->pose_tolerance_deg > 0.0)) {
        std::fprintf(stderr, "--pose-tolerance wants M,DEG, both > 0, e.g. 0.5,30\n");
        return false;
      }
    } else if (flag == "--render-threads") {
      char* end = nullptr;
      const long n = std::strtol(value.c_str(), &end, 10);
      if (end == value.c_str() || *end != '\0' || n < 1 || n > 256) {
        std::fprintf(stderr, "--render-threads wants a count in 1..256\n");
        return false;
      }
      options->render_threads = static_cast<int>(n);
    } else {
      std::fprintf(stderr, "unknown flag %s\n", flag.c_str());
      return false;
    }
  }
  if (beams_given && options->model == "kinect_v1") {
    std::fprintf(stderr, "--beams: the kinect_v1 preset has one beam per pixel (--model hand)\n");
    return false;
  }
  if (!(options->resolution_m >= 0.001 && options->resolution_m <= 10.0)) {
    std::fprintf(stderr, "--resolution must lie in [0.001, 10] m\n");
    return false;
  }
  return true;
}

inline std::string CommandLine(int argc, char** argv) {
  std::string line;
  for (int i = 0; i < argc; ++i) line += (i ? " " : "") + std::string(argv[i]);
  return line;
}

inline std::string LoadAverage() {
  std::ifstream in("/proc/loadavg");
  std::string a, b, c;
  in >> a >> b >> c;
  return a + " " + b + " " + c;
}

// ---- configuration (the same file for fusiond and the in-process map) ----------------------

// The sensor block: the kinect_v1 preset, or the Kinect of e2e_tum_test.cc with cols x rows
// beams (the FOV covers every pixel, principal point off centre), sigma(r) = 0.0012 + 0.0019
// (r - 0.4)^2 m.
inline std::string SensorText(const Options& options) {
  if (options.model == "kinect_v1") {
    return "sensors { id: \"" + std::string(kSensorId) +
           "\" preset: \"kinect_v1\" queue_depth: 20 }\n";
  }
  const double fov_h_deg = 2.0 * std::atan(325.1 / 520.9) * 180.0 / kPi + 0.5;
  const double fov_v_deg = 2.0 * std::atan(249.7 / 521.0) * 180.0 / kPi + 0.5;
  const double s2 = 0.0019, s1 = -2.0 * 0.0019 * 0.4, s0 = 0.0012 + 0.0019 * 0.16;
  std::ostringstream config;
  config << "sensors { id: \"" << kSensorId
         << "\" model: \"paper3d\" r_min_m: 0.5 r_max_m: " << kKinectRMaxM << "\n"
         << "  fov_h_deg: " << fov_h_deg << " fov_v_deg: " << fov_v_deg << "\n"
         << "  cols: " << options.cols << " rows: " << options.rows << " epsilon: 0.02\n"
         << "  q_mu { a2: 0 a1: 1 a0: 0 }\n"
         << "  q_sigma { a2: " << s2 << " a1: " << s1 << " a0: " << s0 << " }\n"
         << "  queue_depth: 20 }\n";
  return config.str();
}

inline std::string ConfigText(const Options& options) {
  std::ostringstream config;
  config << SensorText(options) << "map { resolution_m: " << options.resolution_m
         << " render_interval_ms: 100 beam_cell_size_m: " << kBeamCellSizeM;
  if (options.pose_tolerance_m > 0.0) {
    config << " pose_tolerance_m: " << options.pose_tolerance_m
           << " pose_tolerance_deg: " << options.pose_tolerance_deg;
  }
  if (options.render_threads > 0) config << " render_threads: " << options.render_threads;
  config << " }\n"
         << "ingest { reliability: \"reliable\" }\n";
  return config.str();
}

// The sensor and map options fusiond derives from the file (FusionServer::Start does the same).
struct CoreSetup {
  fusion::service::SensorSetup sensor;
  fusion::WorldMapOptions map;
};

inline std::optional<CoreSetup> CoreSetupFromFile(const std::string& path) {
  v1::ServiceConfig config = fusion::service::DefaultConfig();
  if (const fusion::Status loaded = fusion::service::LoadConfigFile(path, &config); !loaded.ok()) {
    std::fprintf(stderr, "configuration: %s\n", loaded.message().c_str());
    return std::nullopt;
  }
  auto sensor = fusion::service::SensorSetupFromConfig(config.sensors(0));
  auto map = fusion::service::WorldMapOptionsFromConfig(config.map());
  if (!sensor.ok() || !map.ok()) {
    std::fprintf(stderr, "configuration: %s\n",
                 (sensor.ok() ? map.status() : sensor.status()).message().c_str());
    return std::nullopt;
  }
  return CoreSetup{*sensor, *map};
}

// ---- child processes -----------------------------------------------------------------------

// argv through a shell that joins stderr to stdout (which Subprocess reads).
inline std::vector<std::string> WithStderr(std::vector<std::string> argv) {
  argv.insert(argv.begin(), {"/bin/sh", "-c", "exec \"$0\" \"$@\" 2>&1"});
  return argv;
}

struct ToolRun {
  int exit_code = -1;
  double elapsed_s = 0;
  std::string output;
};

inline ToolRun RunTool(const std::vector<std::string>& argv, std::chrono::seconds timeout) {
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

// ---- results -------------------------------------------------------------------------------

struct Row {
  std::string method;
  double time_s = NAN;
  std::uint64_t leaves = 0;
  double memory_bytes = 0;
  double cpu_s = NAN;  // CPU time of the process(es) doing the work, all threads
};

}  // namespace fusion::tum_map_bench
