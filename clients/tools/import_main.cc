// fusion-import: converts recorded range data (TUM RGB-D, PCD, OctoMap scan graphs, x y z
// scans) into a fusion recording that fusion-replay publishes.
#include <unistd.h>

#include <cstdio>
#include <cstring>
#include <memory>
#include <string>
#include <vector>

#include "fusion/clients/cli.h"
#include "fusion/clients/importers.h"
#include "fusion/clients/recording.h"

namespace {

using fusion::clients::Status;

constexpr const char* kUsage = R"(fusion-import: convert recorded range data into a fusion recording

Usage: fusion-import SUBCOMMAND [options] INPUT... -o OUTPUT.frec
       fusion-import SUBCOMMAND --help

Subcommands:
  tum     TUM RGB-D sequence directory (groundtruth.txt + depth/*.png) -> organized clouds
  pcd     PCD files (ascii, binary, binary_compressed), one cloud per file
  graph   OctoMap binary scan graph (.graph), one cloud per node
  scan    plain "x y z" text scans (.bz2 allowed), one cloud per file (or per NODE line)

Every cloud keeps its points in the sensor frame (metres, NaN = no return) and the sensor's
pose in the world frame. Inspect the result with: fusion-replay --list OUTPUT.frec
)";

constexpr const char* kCommonOptions = R"(
Common options:
  -o, --output FILE      recording to write (required)
  --sensor-id ID         sensor id of every cloud (default: %s)
  --help                 this text
)";

constexpr const char* kTumUsage = R"(fusion-import tum DIR -o OUT.frec [options]

DIR holds groundtruth.txt ("depth/<stamp>.png tx ty tz qx qy qz qw" per line: pose of the
optical frame in the world) and depth/*.png (16-bit, value / depth-scale = depth along the
optical axis in metres, 0 = missing -> NaN). Stamps come from the file names.
  --stride N            keep every N-th pixel in both directions (default 1: 640x480)
  --fx PX --fy PX       focal lengths in pixels (default 520.9, 521.0: TUM fr2)
  --cx PX --cy PX       principal point in pixels (default 325.1, 249.7)
  --depth-scale UNITS   PNG units per metre (default 5000)
  --groundtruth FILE    pose list inside DIR (default groundtruth.txt)
  --max-frames N        stop after N frames (default: all)
)";

constexpr const char* kPcdUsage = R"(fusion-import pcd FILE.pcd... -o OUT.frec [options]

Fields x y z (float or double) are read, others ignored; organized clouds stay organized.
VIEWPOINT (tx ty tz qw qx qy qz) is the sensor's pose: points are re-expressed in the sensor
frame and the viewpoint becomes the pose.
  --ignore-viewpoint    take the points as stored (sensor frame) and ignore VIEWPOINT
  --pose tx,ty,tz[,qx,qy,qz,qw]   sensor pose in the world (metres, quaternion) for files
                                  whose VIEWPOINT is the identity or ignored
  --start-time S        stamp of the first cloud, seconds since the epoch (default 0)
  --period S            time between clouds in seconds (default 1)
)";

constexpr const char* kGraphUsage = R"(fusion-import graph FILE.graph -o OUT.frec [options]

OctoMap's binary scan graph (octomap::ScanGraph::writeBinary, e.g. from log2graph): one cloud
per node, points in the node frame, node pose -> sensor pose.
  --start-time S        stamp of the first node (default 0)
  --period S            time between nodes in seconds (default 1)
)";

constexpr const char* kScanUsage = R"(fusion-import scan FILE... -o OUT.frec [options]

Plain text, one "x y z" (metres, scanner frame) per line; FILE.bz2 is decompressed with
bzip2 -dc. Lines "NODE x y z roll pitch yaw" (OctoMap log format) start a new cloud taken
at that pose. Unorganized clouds (width = point count, height = 1).
  --pose tx,ty,tz[,qx,qy,qz,qw]   scanner pose in the world for points before any NODE
                                  line (default: the origin)
  --start-time S        stamp of the first cloud (default 0)
  --period S            time between clouds in seconds (default 1)
)";

int Fail(const std::string& message) {
  std::fprintf(stderr, "fusion-import: %s\n", message.c_str());
  return 1;
}

int UsageError(const std::string& message, const std::string& sub) {
  std::fprintf(stderr, "fusion-import %s: %s (see fusion-import %s --help)\n", sub.c_str(),
               message.c_str(), sub.c_str());
  return 2;
}

void PrintUsage(const char* text, const char* default_id) {
  std::fputs(text, stdout);
  std::printf(kCommonOptions, default_id);
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) {
    std::fputs(kUsage, stderr);
    return 2;
  }
  const std::string sub = argv[1];
  if (sub == "--help" || sub == "-h" || sub == "help") {
    std::fputs(kUsage, stdout);
    return 0;
  }
  const char* usage = nullptr;
  const char* default_id = nullptr;
  if (sub == "tum") usage = kTumUsage, default_id = "tum";
  if (sub == "pcd") usage = kPcdUsage, default_id = "pcd";
  if (sub == "graph") usage = kGraphUsage, default_id = "scanner";
  if (sub == "scan") usage = kScanUsage, default_id = "scanner";
  if (usage == nullptr) {
    std::fprintf(stderr, "fusion-import: unknown subcommand '%s'\n\n%s", sub.c_str(), kUsage);
    return 2;
  }

  std::string output, sensor_id = default_id;
  std::vector<std::string> inputs;
  fusion::clients::TumOptions tum;
  fusion::v1::RecordedPose pose;
  pose.set_qw(1.0);
  bool pose_given = false, ignore_viewpoint = false;
  double start_time_s = 0, period_s = 1;
  for (int i = 2; i < argc; ++i) {
    const std::string arg = argv[i];
    const auto value = [&](std::string* out) {
      if (i + 1 >= argc) return false;
      *out = argv[++i];
      return true;
    };
    std::string v;
    Status s;
    std::uint64_t n = 0;
    if (arg == "--help" || arg == "-h") {
      PrintUsage(usage, default_id);
      return 0;
    } else if (sub == "pcd" && arg == "--ignore-viewpoint") {
      ignore_viewpoint = true;
    } else if (arg.size() > 1 && arg[0] == '-' && !value(&v)) {
      return UsageError(arg + " needs a value", sub);
    } else if (arg == "-o" || arg == "--output") {
      output = v;
    } else if (arg == "--sensor-id") {
      sensor_id = v;
    } else if (sub == "tum" && arg == "--stride") {
      s = fusion::clients::ParseUint(arg, v, &n);
      tum.stride = static_cast<std::uint32_t>(n);
      if (s.ok() && (n == 0 || n > 640)) s = Status::Error("--stride must be 1..640");
    } else if (sub == "tum" && arg == "--fx") {
      s = fusion::clients::ParseDouble(arg, v, &tum.fx_px);
    } else if (sub == "tum" && arg == "--fy") {
      s = fusion::clients::ParseDouble(arg, v, &tum.fy_px);
    } else if (sub == "tum" && arg == "--cx") {
      s = fusion::clients::ParseDouble(arg, v, &tum.cx_px);
    } else if (sub == "tum" && arg == "--cy") {
      s = fusion::clients::ParseDouble(arg, v, &tum.cy_px);
    } else if (sub == "tum" && arg == "--depth-scale") {
      s = fusion::clients::ParseDouble(arg, v, &tum.depth_scale);
    } else if (sub == "tum" && arg == "--groundtruth") {
      tum.groundtruth = v;
    } else if (sub == "tum" && arg == "--max-frames") {
      s = fusion::clients::ParseUint(arg, v, &tum.max_frames);
    } else if ((sub == "pcd" || sub == "scan") && arg == "--pose") {
      s = fusion::clients::ParsePose(arg, v, &pose);
      pose_given = true;
    } else if (sub != "tum" && arg == "--start-time") {
      s = fusion::clients::ParseDouble(arg, v, &start_time_s);
    } else if (sub != "tum" && arg == "--period") {
      s = fusion::clients::ParseDouble(arg, v, &period_s);
      if (s.ok() && period_s < 0) s = Status::Error("--period must not be negative");
    } else if (arg.size() > 1 && arg[0] == '-') {
      return UsageError("unknown option " + arg, sub);
    } else {
      inputs.push_back(arg);
    }
    if (!s.ok()) return UsageError(s.message(), sub);
  }
  if (output.empty()) return UsageError("missing -o OUTPUT", sub);
  if (inputs.empty()) return UsageError("missing input", sub);
  if ((sub == "tum" || sub == "graph") && inputs.size() != 1) {
    return UsageError("expects exactly one input", sub);
  }
  if (sensor_id.empty()) return UsageError("--sensor-id must not be empty", sub);

  std::string source = sub + ":";
  for (const auto& in : inputs) source += " " + in;
  std::unique_ptr<fusion::clients::RecordingWriter> writer;
  if (Status s =
          fusion::clients::RecordingWriter::Create(output, "fusion-import " + sub, source, &writer);
      !s.ok()) {
    return Fail(s.message());
  }
  std::uint64_t points = 0;
  const bool tty = isatty(STDERR_FILENO) != 0;
  const auto append = [&](fusion::v1::RecordedCloud&& cloud) {
    points += cloud.xyz_f32le().size() / 12;
    Status s = writer->Append(cloud);
    if (s.ok() && tty) {
      std::fprintf(stderr, "\rfusion-import: %llu clouds",
                   static_cast<unsigned long long>(writer->records_written()));
    }
    return s;
  };
  Status status;
  std::uint64_t sequence = 0;
  const auto identify = [&](fusion::v1::RecordedCloud* cloud, const std::string& origin) {
    fusion::clients::SetIdentity(sensor_id, sequence + 1, start_time_s + period_s * sequence,
                                 origin, cloud);
    ++sequence;
  };
  if (sub == "tum") {
    tum.directory = inputs[0];
    tum.sensor_id = sensor_id;
    status = fusion::clients::ImportTum(tum, append);
  } else if (sub == "pcd") {
    for (const auto& path : inputs) {
      fusion::v1::RecordedCloud cloud;
      status = fusion::clients::ReadPcd(path, &cloud, !ignore_viewpoint);
      if (!status.ok()) break;
      if (const double behind = fusion::clients::FractionBehindSensor(cloud); behind > 0.5) {
        std::fprintf(stderr,
                     "fusion-import: warning: %s: %.0f%% of the points lie behind the sensor "
                     "(z < 0)%s\n",
                     path.c_str(), 100 * behind,
                     ignore_viewpoint ? "" : "; if its VIEWPOINT is wrong, use --ignore-viewpoint");
      }
      if (pose_given) {
        if (!(cloud.t_world_sensor().tx() == 0 && cloud.t_world_sensor().ty() == 0 &&
              cloud.t_world_sensor().tz() == 0 && cloud.t_world_sensor().qw() == 1.0)) {
          status = Status::Error(path + ": has a non-identity VIEWPOINT; drop --pose to use it");
          break;
        }
        *cloud.mutable_t_world_sensor() = pose;
      }
      identify(&cloud, path);
      status = append(std::move(cloud));
      if (!status.ok()) break;
    }
  } else {
    for (const auto& path : inputs) {
      std::vector<fusion::v1::RecordedCloud> clouds;
      status = sub == "graph" ? fusion::clients::ReadScanGraph(path, &clouds)
                              : fusion::clients::ReadXyzScan(path, pose, &clouds);
      if (!status.ok()) break;
      for (auto& cloud : clouds) {
        identify(&cloud, path);
        status = append(std::move(cloud));
        if (!status.ok()) break;
      }
      if (!status.ok()) break;
    }
  }
  if (tty && writer->records_written() > 0) std::fputc('\n', stderr);
  const Status closed = writer->Close();
  if (!status.ok() && writer->records_written() == 0) {
    std::remove(output.c_str());  // nothing worth keeping
    return Fail(status.message());
  }
  if (!status.ok()) {
    std::fprintf(stderr, "fusion-import: %s\n", status.message().c_str());
    std::fprintf(stderr, "fusion-import: %s keeps the %llu clouds imported before the error\n",
                 output.c_str(), static_cast<unsigned long long>(writer->records_written()));
    return 1;
  }
  if (!closed.ok()) return Fail(closed.message());
  std::printf("imported %llu clouds (%llu points) into %s\n",
              static_cast<unsigned long long>(writer->records_written()),
              static_cast<unsigned long long>(points), output.c_str());
  return 0;
}
