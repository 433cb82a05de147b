// fusion-sim-sensor: a simulated range sensor (the paper's SR-3000 or STOC presets) that
// ray-casts a scene with the sensor's own noise model and publishes the clouds over DDS.
#include <unistd.h>

#include <Eigen/Geometry>
#include <atomic>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <fstream>
#include <memory>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "fusion/clients/cli.h"
#include "fusion/clients/dds_io.h"
#include "fusion/core/sensor.h"
#include "fusion/sim/experiment.h"
#include "fusion/sim/scene.h"
#include "fusion/sim/simulator.h"

namespace {

using fusion::clients::Status;
using Clock = std::chrono::steady_clock;

constexpr const char* kUsage = R"(fusion-sim-sensor: publish simulated point clouds of a scene

Usage: fusion-sim-sensor --preset sr3000|stoc [options]
  --preset NAME        sensor model: sr3000 (time of flight) or stoc (stereo), paper Table I
  --sensor-id ID       id on the wire (default: the preset name)
  --scene paper-board|FILE  scene to ray-cast (default paper-board: the paper's Fig. 5 board
                       and floor; FILE: the scene format of core/sim/include/fusion/sim/scene.h)
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

std::atomic<bool> g_stop{false};
void OnSignal(int) { g_stop = true; }

int UsageError(const std::string& message) {
  std::fprintf(stderr, "fusion-sim-sensor: %s (see fusion-sim-sensor --help)\n", message.c_str());
  return 2;
}

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

}  // namespace

int main(int argc, char** argv) {
  std::string preset, sensor_id, scene_name = "paper-board", topic = fusion::clients::kPointsTopic;
  std::string pose_text, waypoints_path;
  double rate_hz = 5.0;
  std::uint64_t frames = 0, cols = 0, rows = 0, seed = 1, domain = 0, wait_readers = 0;
  bool noise = true;
  fusion::clients::PointsQos qos;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    Status s;
    if (arg == "--help" || arg == "-h") {
      std::fputs(kUsage, stdout);
      return 0;
    } else if (arg == "--no-noise") {
      noise = false;
    } else if (arg == "--reliable") {
      qos.reliable = true;
    } else if (arg.size() > 2 && arg[0] == '-') {
      if (i + 1 >= argc) return UsageError(arg + " needs a value");
      const std::string v = argv[++i];
      if (arg == "--preset") {
        preset = v;
      } else if (arg == "--sensor-id") {
        sensor_id = v;
      } else if (arg == "--scene") {
        scene_name = v;
      } else if (arg == "--topic") {
        topic = v;
      } else if (arg == "--pose") {
        pose_text = v;
      } else if (arg == "--waypoints") {
        waypoints_path = v;
      } else if (arg == "--rate") {
        s = fusion::clients::ParseDouble(arg, v, &rate_hz);
        if (s.ok() && !(rate_hz > 0 && rate_hz <= 1000))
          s = Status::Error("--rate must be in (0, 1000]");
      } else if (arg == "--frames") {
        s = fusion::clients::ParseUint(arg, v, &frames);
      } else if (arg == "--cols") {
        s = fusion::clients::ParseUint(arg, v, &cols);
      } else if (arg == "--rows") {
        s = fusion::clients::ParseUint(arg, v, &rows);
      } else if (arg == "--seed") {
        s = fusion::clients::ParseUint(arg, v, &seed);
      } else if (arg == "--wait-readers") {
        s = fusion::clients::ParseUint(arg, v, &wait_readers);
      } else if (arg == "--domain") {
        s = fusion::clients::ParseUint(arg, v, &domain);
        if (s.ok() && domain > 230) s = Status::Error("--domain must be 0..230");
      } else {
        return UsageError("unknown option " + arg);
      }
    } else {
      return UsageError("unexpected argument " + arg);
    }
    if (!s.ok()) return UsageError(s.message());
  }
  if (preset.empty()) return UsageError("missing --preset");
  if (sensor_id.empty()) sensor_id = preset;
  if ((cols == 0) != (rows == 0) || cols > 4096 || rows > 4096) {
    return UsageError("--cols and --rows go together, 1..4096 each");
  }

  // The paper's mounting and simulation options for the preset, overridden by the flags.
  fusion::sim::SensorRun run;
  bool found = false;
  for (const auto& r : fusion::sim::PaperSensorRuns()) {
    if (r.id == preset) run = r, found = true;
  }
  if (!found) {
    const auto spec = fusion::SensorPreset(preset);
    if (!spec) {
      std::string names;
      for (const auto& n : fusion::SensorPresetNames()) names += " " + n;
      return UsageError("unknown preset '" + preset + "' (known:" + names + ")");
    }
    run.spec = *spec;
  }
  if (cols != 0) {
    run.spec =
        fusion::sim::WithTessellation(run.spec, static_cast<int>(cols), static_cast<int>(rows));
  }
  run.sim.seed = seed;
  run.sim.add_noise = noise;

  std::vector<Waypoint> waypoints;
  if (!pose_text.empty() && !waypoints_path.empty())
    return UsageError("--pose or --waypoints, not both");
  if (!pose_text.empty()) {
    std::vector<double> v;
    std::stringstream stream(pose_text);
    for (std::string item; std::getline(stream, item, ',');) {
      double d = 0;
      if (Status s = fusion::clients::ParseDouble("--pose", item, &d); !s.ok())
        return UsageError(s.message());
      v.push_back(d);
    }
    if (v.size() != 3 && v.size() != 5)
      return UsageError("--pose: expected x,y,z or x,y,z,yaw_deg,pitch_deg");
    v.resize(5, 0.0);
    waypoints.push_back({0, v[0], v[1], v[2], v[3], v[4]});
  }
  if (!waypoints_path.empty()) {
    if (Status s = LoadWaypoints(waypoints_path, &waypoints); !s.ok()) {
      std::fprintf(stderr, "fusion-sim-sensor: %s\n", s.message().c_str());
      return 1;
    }
  }

  fusion::sim::Scene scene;
  if (scene_name == "paper-board") {
    scene = fusion::sim::PaperBoardScene();
  } else {
    std::string error;
    auto loaded = fusion::sim::LoadSceneFile(scene_name, &error);
    if (!loaded) {
      std::fprintf(stderr, "fusion-sim-sensor: %s: %s\n", scene_name.c_str(), error.c_str());
      return 1;
    }
    scene = std::move(*loaded);
  }

  std::signal(SIGINT, OnSignal);
  std::signal(SIGTERM, OnSignal);
  std::unique_ptr<fusion::clients::PointCloudWriter> writer;
  if (Status s = fusion::clients::PointCloudWriter::Create(static_cast<std::uint32_t>(domain),
                                                           topic, qos, &writer);
      !s.ok()) {
    std::fprintf(stderr, "fusion-sim-sensor: cannot publish: %s\n", s.message().c_str());
    return 1;
  }
  if (wait_readers > 0 &&
      !writer->WaitForReaders(static_cast<std::uint32_t>(wait_readers), std::chrono::seconds(10))) {
    std::fprintf(stderr, "fusion-sim-sensor: only %u readers after 10 s; publishing anyway\n",
                 writer->matched_readers());
  }
  fusion::sim::RangeSimulator simulator(scene, run.spec, run.sim);
  std::printf(
      "fusion-sim-sensor: %s (%s, %dx%d beams) publishing on %s in domain %llu at %.1f Hz\n",
      sensor_id.c_str(), preset.c_str(), run.spec.cols, run.spec.rows, topic.c_str(),
      static_cast<unsigned long long>(domain), rate_hz);
  std::fflush(stdout);

  const auto start = Clock::now();
  const auto period = std::chrono::duration<double>(1.0 / rate_hz);
  auto last_progress = start;
  fusion::v1::RecordedCloud cloud;
  std::uint64_t published = 0;
  for (std::uint64_t k = 0; !g_stop && (frames == 0 || k < frames); ++k) {
    const auto due =
        start + std::chrono::duration_cast<Clock::duration>(period * static_cast<double>(k));
    while (!g_stop && Clock::now() < due) {
      std::this_thread::sleep_until(std::min(due, Clock::now() + std::chrono::milliseconds(100)));
    }
    if (g_stop) break;
    const double t_s = std::chrono::duration<double>(Clock::now() - start).count();
    const Eigen::Isometry3d T_world_sensor =
        waypoints.empty() ? run.T_world_sensor : PoseOf(Interpolate(waypoints, t_s));
    const fusion::sim::OrganizedCloud frame = simulator.Capture(T_world_sensor);

    cloud.Clear();
    cloud.set_sensor_id(sensor_id);
    cloud.set_sequence_number(k + 1);
    const std::int64_t now_ns = fusion::clients::UnixNowNs();
    cloud.mutable_stamp()->set_sec(static_cast<std::int32_t>(now_ns / 1000000000));
    cloud.mutable_stamp()->set_nanosec(static_cast<std::uint32_t>(now_ns % 1000000000));
    const Eigen::Quaterniond q(T_world_sensor.rotation());
    auto* pose = cloud.mutable_t_world_sensor();
    pose->set_tx(T_world_sensor.translation().x());
    pose->set_ty(T_world_sensor.translation().y());
    pose->set_tz(T_world_sensor.translation().z());
    pose->set_qx(q.x());
    pose->set_qy(q.y());
    pose->set_qz(q.z());
    pose->set_qw(q.w());
    cloud.set_width(static_cast<std::uint32_t>(frame.cols));
    cloud.set_height(static_cast<std::uint32_t>(frame.rows));
    cloud.set_xyz_f32le(
        std::string(reinterpret_cast<const char*>(frame.xyz.data()), frame.xyz.size() * 4));
    cloud.set_beyond_range(std::string(frame.beyond_range.begin(), frame.beyond_range.end()));
    if (Status s = writer->Write(cloud); !s.ok()) {
      std::fprintf(stderr, "fusion-sim-sensor: %s\n", s.message().c_str());
      return 1;
    }
    ++published;
    const auto now = Clock::now();
    if (now - last_progress >= std::chrono::seconds(5)) {
      std::fprintf(stderr, "fusion-sim-sensor: %llu frames, %u readers\n",
                   static_cast<unsigned long long>(published), writer->matched_readers());
      last_progress = now;
    }
  }
  if (qos.reliable) {
    if (Status s = writer->WaitForAcks(std::chrono::seconds(10)); !s.ok()) {
      std::fprintf(stderr, "fusion-sim-sensor: %s\n", s.message().c_str());
    }
  }
  std::printf("fusion-sim-sensor: published %llu frames\n",
              static_cast<unsigned long long>(published));
  return 0;
}
