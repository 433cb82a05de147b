// fusion-sim-sensor: a simulated range sensor (the paper's SR-3000 or STOC presets) that
// ray-casts a scene with the sensor's own noise model and publishes the clouds over DDS.
#include <unistd.h>

#include <Eigen/Geometry>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <memory>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include "fusion/clients/cli.h"
#include "fusion/clients/dds_io.h"
#include "fusion/core/sensor.h"
#include "fusion/sim/experiment.h"
#include "fusion/sim/scene.h"
#include "fusion/sim/simulator.h"

namespace {

using fusion::Status;
using Clock = std::chrono::steady_clock;

constexpr const char* kTool = "fusion-sim-sensor";

constexpr const char* kUsage = R"(fusion-sim-sensor: publish simulated point clouds of a scene

Usage: fusion-sim-sensor --preset sr3000|stoc [options]
  --preset NAME        sensor model: sr3000 (time of flight) or stoc (stereo), paper Table I
  --sensor-id ID       id on the wire (default: the preset name)
  --scene paper-board|FILE  scene to ray-cast (default paper-board: the paper's Fig. 5 board
                       and floor; FILE: the scene format of core/sim/include/fusion/sim/scene.h;
                       objects with from / until / path move on the tool's clock, seconds
                       since the first frame, like --waypoints)
  --pose x,y,z[,yaw_deg,pitch_deg]  sensor position in the world (metres), looking along +x
                       rotated by yaw (left) and pitch (down) (default: the paper's mounting)
  --waypoints FILE     moving sensor: lines "t_s x y z yaw_deg pitch_deg", linearly
                       interpolated, held after the last one
  --rate HZ            frames per second (default 5)
  --frames N           stop after N frames (default 0: until SIGINT/SIGTERM)
  --cols C --rows R    coarser beam grid, same field of view (default: the preset's; stoc
                       defaults to 160 x 120 like the paper experiment)
  --seed N             noise seed (default 1)
  --no-noise           exact ranges
  --domain N           DDS domain id (default 0)
  --topic NAME         topic (default fusion/points)
  --reliable           reliable keep-all writer (default: best effort, sensor data)
  --wait-readers N     wait up to 10 s for N matched readers before the first frame (default 0)
  --help               this text
)";

struct Waypoint {
  double t_s, x, y, z, yaw_deg, pitch_deg;
};

Eigen::Isometry3d PoseOf(const Waypoint& w) {
  constexpr double kDegToRad = M_PI / 180.0;
  return fusion::sim::ForwardLookingPose(Eigen::Vector3d(w.x, w.y, w.z), w.yaw_deg * kDegToRad,
                                         w.pitch_deg * kDegToRad);
}

Waypoint Interpolate(const std::vector<Waypoint>& path, double t_s) {
  if (t_s <= path.front().t_s) return path.front();
  for (std::size_t i = 1; i < path.size(); ++i) {
    if (t_s <= path[i].t_s) {
      const Waypoint& a = path[i - 1];
      const Waypoint& b = path[i];
      const double f = (t_s - a.t_s) / (b.t_s - a.t_s);
      const auto mix = [f](double u, double v) { return u + f * (v - u); };
      return {t_s,
              mix(a.x, b.x),
              mix(a.y, b.y),
              mix(a.z, b.z),
              mix(a.yaw_deg, b.yaw_deg),
              mix(a.pitch_deg, b.pitch_deg)};
    }
  }
  return path.back();
}

Status LoadWaypoints(const std::string& path, std::vector<Waypoint>* waypoints) {
  std::ifstream in(path);
  if (!in) return Status::Error("cannot open " + path);
  std::string line;
  for (int number = 1; std::getline(in, line); ++number) {
    if (line.find_first_not_of(" \t\r") == std::string::npos || line[0] == '#') continue;
    std::istringstream fields(line);
    Waypoint w{};
    if (!(fields >> w.t_s >> w.x >> w.y >> w.z >> w.yaw_deg >> w.pitch_deg)) {
      return Status::Error(path + ":" + std::to_string(number) +
                           ": expected 't_s x y z yaw_deg pitch_deg'");
    }
    if (!waypoints->empty() && w.t_s <= waypoints->back().t_s) {
      return Status::Error(path + ":" + std::to_string(number) + ": times must increase");
    }
    waypoints->push_back(w);
  }
  if (waypoints->empty()) return Status::Error(path + ": no waypoints");
  return Status::Ok();
}

struct Options {
  std::string preset, sensor_id, scene_name = "paper-board", topic = fusion::clients::kPointsTopic;
  std::string pose_text, waypoints_path;
  double rate_hz = 5.0;
  std::uint64_t frames = 0, cols = 0, rows = 0, seed = 1, domain = 0, wait_readers = 0;
  bool noise = true;
  fusion::clients::PointsQos qos;
};

// The option `arg` that takes value `v`; false if `arg` is none.
bool ApplyValue(const std::string& arg, const std::string& v, Options* o, Status* s) {
  std::string* const text = arg == "--preset"      ? &o->preset
                            : arg == "--sensor-id" ? &o->sensor_id
                            : arg == "--scene"     ? &o->scene_name
                            : arg == "--topic"     ? &o->topic
                            : arg == "--pose"      ? &o->pose_text
                            : arg == "--waypoints" ? &o->waypoints_path
                                                   : nullptr;
  std::uint64_t* const number = arg == "--frames"         ? &o->frames
                                : arg == "--cols"         ? &o->cols
                                : arg == "--rows"         ? &o->rows
                                : arg == "--seed"         ? &o->seed
                                : arg == "--wait-readers" ? &o->wait_readers
                                                          : nullptr;
  if (text != nullptr) {
    *text = v;
  } else if (number != nullptr) {
    *s = fusion::clients::ParseUint(arg, v, number);
  } else if (arg == "--rate") {
    *s = fusion::clients::ParseDouble(arg, v, &o->rate_hz);
    if (s->ok() && !(o->rate_hz > 0 && o->rate_hz <= 1000))
      *s = Status::Error("--rate must be in (0, 1000]");
  } else if (arg == "--domain") {
    *s = fusion::clients::ParseDomain(arg, v, &o->domain);
  } else {
    return false;
  }
  return true;
}

// Returns the exit code when the tool is done already (--help, a bad command line).
std::optional<int> ParseFlags(int argc, char** argv, Options* o) {
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    Status s;
    if (fusion::clients::IsHelpFlag(arg)) {
      return fusion::clients::PrintHelp(kUsage);
    } else if (arg == "--no-noise") {
      o->noise = false;
    } else if (arg == "--reliable") {
      o->qos.reliable = true;
    } else if (arg.size() > 2 && arg[0] == '-') {
      std::string v;
      if (!fusion::clients::TakeValue(argc, argv, &i, &v)) {
        // An unknown option last on the line is unknown, not one that lacks its value.
        Options probe;
        Status ignored;
        const bool known = ApplyValue(arg, "1", &probe, &ignored);
        return fusion::clients::UsageError(
            kTool, known ? arg + " needs a value" : "unknown option " + arg);
      }
      if (!ApplyValue(arg, v, o, &s)) {
        return fusion::clients::UsageError(kTool, "unknown option " + arg);
      }
    } else {
      return fusion::clients::UsageError(kTool, "unexpected argument " + arg);
    }
    if (!s.ok()) return fusion::clients::UsageError(kTool, s.message());
  }
  if (o->preset.empty()) return fusion::clients::UsageError(kTool, "missing --preset");
  if (o->sensor_id.empty()) o->sensor_id = o->preset;
  if ((o->cols == 0) != (o->rows == 0) || o->cols > 4096 || o->rows > 4096) {
    return fusion::clients::UsageError(kTool, "--cols and --rows go together, 1..4096 each");
  }
  return std::nullopt;
}

// The paper's mounting and simulation options for the preset, overridden by the flags.
std::optional<int> ResolveRun(const Options& o, fusion::sim::SensorRun* run) {
  bool found = false;
  for (const auto& r : fusion::sim::PaperSensorRuns()) {
    if (r.id == o.preset) *run = r, found = true;
  }
  if (!found) {
    const auto spec = fusion::SensorPreset(o.preset);
    if (!spec) {
      std::string names;
      for (const auto& n : fusion::SensorPresetNames()) names += " " + n;
      return fusion::clients::UsageError(kTool,
                                         "unknown preset '" + o.preset + "' (known:" + names + ")");
    }
    run->spec = *spec;
  }
  if (o.cols != 0) {
    run->spec = fusion::sim::WithTessellation(run->spec, static_cast<int>(o.cols),
                                              static_cast<int>(o.rows));
  }
  run->sim.seed = o.seed;
  run->sim.add_noise = o.noise;
  return std::nullopt;
}

// --pose (one waypoint) or --waypoints; none leaves the preset's mounting.
std::optional<int> LoadPath(const Options& o, std::vector<Waypoint>* waypoints) {
  if (!o.pose_text.empty() && !o.waypoints_path.empty())
    return fusion::clients::UsageError(kTool, "--pose or --waypoints, not both");
  if (!o.pose_text.empty()) {
    std::vector<double> v;
    std::stringstream stream(o.pose_text);
    for (std::string item; std::getline(stream, item, ',');) {
      double d = 0;
      if (Status s = fusion::clients::ParseDouble("--pose", item, &d); !s.ok())
        return fusion::clients::UsageError(kTool, s.message());
      v.push_back(d);
    }
    if (v.size() != 3 && v.size() != 5)
      return fusion::clients::UsageError(kTool,
                                         "--pose: expected x,y,z or x,y,z,yaw_deg,pitch_deg");
    v.resize(5, 0.0);
    waypoints->push_back({0, v[0], v[1], v[2], v[3], v[4]});
  }
  if (!o.waypoints_path.empty()) {
    if (Status s = LoadWaypoints(o.waypoints_path, waypoints); !s.ok()) {
      return fusion::clients::Fail(kTool, s.message());
    }
  }
  return std::nullopt;
}

std::optional<int> LoadScene(const std::string& scene_name, fusion::sim::Scene* scene) {
  if (scene_name == "paper-board") {
    *scene = fusion::sim::PaperBoardScene();
    return std::nullopt;
  }
  std::string error;
  auto loaded = fusion::sim::LoadSceneFile(scene_name, &error);
  if (!loaded) return fusion::clients::Fail(kTool, scene_name + ": " + error);
  *scene = std::move(*loaded);
  return std::nullopt;
}

// Frame k (from 0) taken at T_world_sensor, stamped now, as the wire's cloud.
void ToCloud(const Options& o, std::uint64_t k, const Eigen::Isometry3d& T_world_sensor,
             const fusion::sim::OrganizedCloud& frame, fusion::v1::RecordedCloud* cloud) {
  cloud->Clear();
  cloud->set_sensor_id(o.sensor_id);
  cloud->set_sequence_number(k + 1);
  *cloud->mutable_stamp() = fusion::clients::TimeFromUnixNs(fusion::clients::UnixNowNs());
  const Eigen::Quaterniond q(T_world_sensor.rotation());
  auto* pose = cloud->mutable_t_world_sensor();
  pose->set_tx(T_world_sensor.translation().x());
  pose->set_ty(T_world_sensor.translation().y());
  pose->set_tz(T_world_sensor.translation().z());
  pose->set_qx(q.x());
  pose->set_qy(q.y());
  pose->set_qz(q.z());
  pose->set_qw(q.w());
  cloud->set_width(static_cast<std::uint32_t>(frame.cols));
  cloud->set_height(static_cast<std::uint32_t>(frame.rows));
  cloud->set_xyz_f32le(
      std::string(reinterpret_cast<const char*>(frame.xyz.data()), frame.xyz.size() * 4));
  cloud->set_beyond_range(std::string(frame.beyond_range.begin(), frame.beyond_range.end()));
}

// Captures and publishes frames at --rate until --frames or a stop request; *published
// counts them. Returns the first write error.
Status PublishFrames(const Options& o, const fusion::sim::SensorRun& run,
                     const std::vector<Waypoint>& waypoints, fusion::sim::RangeSimulator* simulator,
                     fusion::clients::PointCloudWriter* writer, std::uint64_t* published) {
  const auto start = Clock::now();
  const auto period = std::chrono::duration<double>(1.0 / o.rate_hz);
  auto last_progress = start;
  fusion::v1::RecordedCloud cloud;
  for (std::uint64_t k = 0; !fusion::clients::StopRequested() && (o.frames == 0 || k < o.frames);
       ++k) {
    const auto due =
        start + std::chrono::duration_cast<Clock::duration>(period * static_cast<double>(k));
    if (!fusion::clients::SleepUntilOrStop(due)) break;
    const double t_s = std::chrono::duration<double>(Clock::now() - start).count();
    const Eigen::Isometry3d T_world_sensor =
        waypoints.empty() ? run.T_world_sensor : PoseOf(Interpolate(waypoints, t_s));
    ToCloud(o, k, T_world_sensor, simulator->Capture(T_world_sensor, t_s), &cloud);
    if (Status s = writer->Write(cloud); !s.ok()) return s;
    ++*published;
    const auto now = Clock::now();
    if (now - last_progress >= std::chrono::seconds(5)) {
      std::fprintf(stderr, "fusion-sim-sensor: %llu frames, %u readers\n",
                   static_cast<unsigned long long>(*published), writer->matched_readers());
      last_progress = now;
    }
  }
  return Status::Ok();
}

}  // namespace

int main(int argc, char** argv) {
  Options o;
  if (const auto done = ParseFlags(argc, argv, &o)) return *done;
  fusion::sim::SensorRun run;
  if (const auto done = ResolveRun(o, &run)) return *done;
  std::vector<Waypoint> waypoints;
  if (const auto done = LoadPath(o, &waypoints)) return *done;
  fusion::sim::Scene scene;
  if (const auto done = LoadScene(o.scene_name, &scene)) return *done;

  fusion::clients::InstallStopHandlers();
  std::unique_ptr<fusion::clients::PointCloudWriter> writer;
  if (Status s = fusion::clients::PointCloudWriter::Create(static_cast<std::uint32_t>(o.domain),
                                                           o.topic, o.qos, &writer);
      !s.ok()) {
    return fusion::clients::Fail(kTool, "cannot publish: " + s.message());
  }
  if (o.wait_readers > 0 && !writer->WaitForReaders(static_cast<std::uint32_t>(o.wait_readers),
                                                    std::chrono::seconds(10))) {
    std::fprintf(stderr, "fusion-sim-sensor: only %u readers after 10 s; publishing anyway\n",
                 writer->matched_readers());
  }
  fusion::sim::RangeSimulator simulator(scene, run.spec, run.sim);
  std::printf(
      "fusion-sim-sensor: %s (%s, %dx%d beams) publishing on %s in domain %llu at %.1f Hz\n",
      o.sensor_id.c_str(), o.preset.c_str(), run.spec.cols, run.spec.rows, o.topic.c_str(),
      static_cast<unsigned long long>(o.domain), o.rate_hz);
  std::fflush(stdout);

  std::uint64_t published = 0;
  if (Status s = PublishFrames(o, run, waypoints, &simulator, writer.get(), &published); !s.ok()) {
    return fusion::clients::Fail(kTool, s.message());
  }
  if (o.qos.reliable) {
    if (Status s = writer->WaitForAcks(std::chrono::seconds(10)); !s.ok()) {
      std::fprintf(stderr, "fusion-sim-sensor: %s\n", s.message().c_str());
    }
  }
  std::printf("fusion-sim-sensor: published %llu frames\n",
              static_cast<unsigned long long>(published));
  return fusion::clients::kExitOk;
}
