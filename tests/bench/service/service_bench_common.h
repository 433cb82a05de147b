// service_bench (service_bench.cc): what every scenario uses: the clock and its units, the
// paper's board voxel, percentiles, and the command line with its configuration overrides.
#pragma once

#include <google/protobuf/text_format.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include "../../support/request_helpers.h"
#include "fusion/sim/simulator.h"
#include "fusion/v1/config.pb.h"
#include "fusion/v1/map_service.pb.h"

namespace fusion::service_bench {

using Clock = std::chrono::steady_clock;
using namespace std::chrono_literals;  // NOLINT: the bench's durations (10s, 2ms)
namespace v1 = fusion::v1;
namespace sim = fusion::sim;

inline const std::string kFusiond = std::string(FUSION_BINARY_DIR) + "/service/fusiond";
inline const Eigen::Vector3d kOnBoard(1.75, 0.0, 0.2);  // a voxel of the paper's board (x = 1.75)

inline double Ms(Clock::duration d) { return std::chrono::duration<double, std::milli>(d).count(); }

using fusion::testing::In;  // a gRPC deadline from now
using fusion::testing::P;   // a point as the wire's Point

// Nearest-rank percentile of unsorted values.
inline double Percentile(std::vector<double> v, double q) {
  if (v.empty()) return NAN;
  std::sort(v.begin(), v.end());
  const auto rank = static_cast<std::size_t>(std::ceil(q * static_cast<double>(v.size())));
  return v[std::min(v.size() - 1, rank == 0 ? 0 : rank - 1)];
}

inline std::string LoadAverage() {
  std::ifstream in("/proc/loadavg");
  std::string a, b, c;
  in >> a >> b >> c;
  return a + " " + b + " " + c;
}

inline std::string ReadFile(const std::string& path) {
  std::ifstream in(path);
  std::stringstream text;
  text << in.rdbuf();
  return text.str();
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

inline bool ParseOptions(int argc, char** argv, BenchOptions* options) {
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
inline std::optional<std::string> WithBenchOverrides(const std::string& base_text,
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

}  // namespace fusion::service_bench
