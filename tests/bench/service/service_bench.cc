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
//
// The scenarios live in service_bench_*.h beside this file (tests/CMakeLists.txt makes one
// program of each .cc file here): _common (clock, options), _fusiond (the process, its client,
// the DDS writers), _queries (small queries, tables), _paper (scenarios 1-4), _moving_drive and
// _moving (scenario 5).
#include <stdlib.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <string>
#include <thread>

#include "service_bench_common.h"
#include "service_bench_moving.h"
#include "service_bench_paper.h"

namespace sb = fusion::service_bench;
using sb::Clock;

int main(int argc, char** argv) {
  sb::BenchOptions options;
  if (argc == 2 && std::string(argv[1]) == "--help") {
    std::printf("%s", sb::kUsage);
    return 0;
  }
  if (!sb::ParseOptions(argc, argv, &options)) return 2;
  const auto bench_start = Clock::now();
  std::printf(
      "# fusiond service benchmark\n\nload average at start (/proc/loadavg): %s; "
      "hardware threads: %u\n\n",
      sb::LoadAverage().c_str(), std::thread::hardware_concurrency());
  char dir_template[] = "/tmp/service_bench_XXXXXX";
  const char* dir = mkdtemp(dir_template);
  if (dir == nullptr) return 1;
  const unsigned domain = 100 + static_cast<unsigned>(getpid()) % 100;
  int code = 0;
  if (options.Runs('1') || options.Runs('2') || options.Runs('3') || options.Runs('4'))
    code = sb::RunPaperScenarios(options, dir, domain);
  // Scenario 5 starts a fusiond of its own, in the same domain once the first one has exited.
  if (code == 0 && options.Runs('5')) code = sb::RunMovingScenario(options, dir, domain);
  std::printf("load average at end: %s; total %.1f s\n", sb::LoadAverage().c_str(),
              std::chrono::duration<double>(Clock::now() - bench_start).count());
  std::filesystem::remove_all(dir);
  return code;
}
