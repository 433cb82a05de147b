// The table of dynamic scenarios (a world that changes, issue 17): for each scenario and map
// configuration, how long the object's voxels stay occupied after it has left them (the trail,
// fusion/sim/dynamic_scenario.h), the false alarms of change detection on the same run
// without the object, and the accuracy of the static board and floor.
//
//   dynamic_scenarios [--resolution M] [--beams COLSxROWS] [--help]
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include "fusion/core/world_map.h"
#include "fusion/sim/dynamic_scenario.h"
#include "fusion/sim/simulator.h"

namespace {

using fusion::WorldMapOptions;
using fusion::sim::DynamicResult;
using fusion::sim::DynamicScenario;

struct Config {
  std::string name;
  WorldMapOptions options;
};

std::vector<Config> Configs(double resolution_m) {
  WorldMapOptions base;
  base.resolution_m = resolution_m;
  std::vector<Config> configs;
  const auto add = [&](const char* name, std::uint32_t run, double history_max) {
    Config c{name, base};
    c.options.beam_grid.change_run = run;
    c.options.history_clamping_max_probability = history_max;
    configs.push_back(c);
  };
  add("change_run 0, history clamp 0.999", 0, 0.999);
  add("change_run 3, history clamp 0.999", 3, 0.999);
  add("change_run 3, history clamp 0.97", 3, 0.97);
  return configs;
}

std::string Percent(double fraction) {
  if (fraction < 0.0) return "-";
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.1f %%", 100.0 * fraction);
  return buf;
}

int Usage(const char* argv0, int code) {
  std::fprintf(code == 0 ? stdout : stderr,
               "usage: %s [--resolution M] [--beams COLSxROWS]\n"
               "  Runs the dynamic scenarios (a crate taken away, a person walking through) with\n"
               "  the simulated SR-3000 and prints the table of BENCHMARKS.md.\n"
               "  --resolution M     map resolution in metres (default 0.02)\n"
               "  --beams COLSxROWS  simulate a coarser tessellation of the SR-3000 (default:\n"
               "                     its own 176x144)\n",
               argv0);
  return code;
}

}  // namespace

int main(int argc, char** argv) {
  double resolution_m = 0.02;
  int cols = 0, rows = 0;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    if (arg == "--help" || arg == "-h") return Usage(argv[0], 0);
    if (arg == "--resolution" && i + 1 < argc) {
      resolution_m = std::atof(argv[++i]);
    } else if (arg == "--beams" && i + 1 < argc) {
      if (std::sscanf(argv[++i], "%dx%d", &cols, &rows) != 2 || cols <= 0 || rows <= 0) {
        return Usage(argv[0], 2);
      }
    } else {
      std::fprintf(stderr, "unknown argument: %s\n", arg.c_str());
      return Usage(argv[0], 2);
    }
  }
  if (!(resolution_m > 0.0)) return Usage(argv[0], 2);
  fusion::SensorSpec spec = *fusion::SensorPreset("sr3000");
  if (cols > 0) spec = fusion::sim::WithTessellation(spec, cols, rows);
  const double rate_hz = 30.0;
  std::printf(
      "SR-3000 (%dx%d beams) at %.0f Hz, resolution %.3f m; trail: voxels the object held "
      "that the map had called occupied, still occupied L frames after it left them\n\n",
      spec.cols, spec.rows, rate_hz, resolution_m);
  std::printf(
      "| scenario | configuration | trail voxels | clear [frames, <= 5 %%] | after 3 "
      "frames | after 1 s | false alarms / beam / frame | static recall | static Brier "
      "| time [s] |\n|---|---|---|---|---|---|---|---|---|---|\n");
  const std::vector<DynamicScenario> scenarios = {
      fusion::sim::CrateRemovedScenario(spec, false), fusion::sim::CrateRemovedScenario(spec, true),
      fusion::sim::WalkerScenario(spec, false), fusion::sim::WalkerScenario(spec, true)};
  for (const DynamicScenario& scenario : scenarios) {
    for (const Config& config : Configs(resolution_m)) {
      const auto start = std::chrono::steady_clock::now();
      const DynamicResult run = fusion::sim::RunDynamicScenario(scenario, config.options);
      const double seconds =
          std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
      DynamicScenario still = scenario;
      still.without_object = true;
      const DynamicResult baseline = fusion::sim::RunDynamicScenario(still, config.options);
      const double false_alarms =
          baseline.beam_readings > 0
              ? static_cast<double>(baseline.changes_detected) / baseline.beam_readings
              : 0.0;
      const int clear = run.ClearFrames(0.05);
      std::printf(
          "| %s | %s | %zu | %s | %s | %s | %.2g | %.3f (%.3f without it) | %.4f (%.4f) "
          "| %.1f |\n",
          scenario.name.c_str(), config.name.c_str(), run.trail_voxels,
          clear < 0 ? "never" : std::to_string(clear).c_str(), Percent(run.TrailAt(3)).c_str(),
          Percent(run.TrailAt(static_cast<int>(rate_hz))).c_str(), false_alarms,
          run.static_accuracy.recall, baseline.static_accuracy.recall, run.static_accuracy.brier,
          baseline.static_accuracy.brier, seconds);
      std::fflush(stdout);
    }
  }
  return 0;
}
