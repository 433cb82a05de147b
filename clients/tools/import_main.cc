// fusion-import: converts recorded range data (TUM RGB-D, PCD, OctoMap scan graphs, x y z
// scans) into a fusion recording that fusion-replay publishes.
#include <unistd.h>

#include <cstdio>
#include <cstring>
#include <memory>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include "fusion/clients/cli.h"
#include "fusion/clients/importers.h"
#include "fusion/clients/recording.h"
#include "fusion/clients/rosbag2.h"
#include "fusion/clients/sensor_block.h"

namespace {

using fusion::Status;

constexpr const char* kTool = "fusion-import";

constexpr const char* kUsage = R"(fusion-import: convert recorded range data into a fusion recording

Usage: fusion-import SUBCOMMAND [options] INPUT... -o OUTPUT.frec
       fusion-import SUBCOMMAND --help

Subcommands:
  tum     TUM RGB-D sequence directory (groundtruth.txt + depth/*.png) -> organized clouds
  pcd     PCD files (ascii, binary, binary_compressed), one cloud per file
  graph   OctoMap binary scan graph (.graph), one cloud per node
  scan    plain "x y z" text scans (.bz2 allowed), one cloud per file (or per NODE line)
  rosbag2 ROS 2 bag (sqlite3 .db3 or MCAP): PointCloud2 or depth Image topic, poses from tf

Every cloud keeps its points in the sensor's optical frame (x right, y down, z forward;
metres, NaN = no return) and that frame's pose in the world. Inspect the result with:
fusion-replay --list OUTPUT.frec. --print-sensor prints the sensors { ... } block of
fusiond's configuration that describes the data (see SUBCOMMAND --help).
)";

constexpr const char* kCommonOptions = R"(
Common options:
  -o, --output FILE      recording to write (required)
  --sensor-id ID         sensor id of every cloud (default: %s)
  --print-sensor         after importing, print the sensors { ... } block of fusiond's
                         configuration (text format) for the data on stdout; everything
                         else goes to stderr
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
--print-sensor: preset "kinect_v1" with pinhole { fx fy cx cy width height stride } of the
import (the image size read, --stride).
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
--print-sensor: organized clouds: pinhole { fx fy cx cy width height stride: 1 } fitted to
the points (u = fx x/z + cx over the columns, v = fy y/z + cy over the rows) with r_min_m /
r_max_m from the ranges seen; unorganized ones: the angular form of `scan --help`. No preset:
add the noise model (q_mu, q_sigma) or a preset by hand.
)";

constexpr const char* kGraphUsage = R"(fusion-import graph FILE.graph -o OUT.frec [options]

OctoMap's binary scan graph (octomap::ScanGraph::writeBinary, e.g. from log2graph): one cloud
per node, points in the node frame, node pose -> sensor pose.
  --frame optical|body  the frame of the nodes' points and poses (default optical: x right,
                        y down, z forward). body (REP-103: x forward, y left, z up; OctoMap's
                        scanners): points rotated into the optical frame, p_optical =
                        R_optical_body p_body, and poses T_world_optical = T_world_node
                        T_body_optical, so the world points stay where they were
  --start-time S        stamp of the first node (default 0)
  --period S            time between nodes in seconds (default 1)
--print-sensor: as for scan.
)";

constexpr const char* kScanUsage = R"(fusion-import scan FILE... -o OUT.frec [options]

Plain text, one "x y z" (metres, in the --frame) per line; FILE.bz2 is decompressed with
bzip2 -dc. Lines "NODE x y z roll pitch yaw" (OctoMap log format: metres, radians) start a
new cloud taken at that pose. Unorganized clouds (width = point count, height = 1).
  --frame optical|body  the frame of the points, of --pose and of NODE poses (default
                        optical: x right, y down, z forward, what fusiond reads). body
                        (REP-103: x forward, y left, z up; OctoMap's sample scan and logs):
                        points rotated into the optical frame, p_optical = R_optical_body
                        p_body, and the recorded pose T_world_optical = T_world_body
                        T_body_optical, so the world points stay R p + t
  --pose tx,ty,tz[,qx,qy,qz,qw]   pose in the world (metres, Hamilton quaternion) of the
                                  --frame for points before any NODE line (default: the
                                  origin); a world point is R(q) p + t
  --start-time S        stamp of the first cloud (default 0)
  --period S            time between clouds in seconds (default 1)
--print-sensor: preset "laser_3d" with the returns' extents in the optical frame (azimuth =
atan2(x, z) to the right, elevation = atan2(-y, hypot(x, z)) up, degrees) widened by one
beam each side, cols and rows of about the returns' spacing, r_min_m / r_max_m from the
ranges seen.
)";

void PrintUsage(const char* text, const char* default_id) {
  std::fputs(text, stdout);
  std::printf(kCommonOptions, default_id);
}

struct Options {
  std::string sub;                   // tum, pcd, graph or scan
  const char* usage = nullptr;       // the subcommand's --help text
  const char* default_id = nullptr;  // its default sensor id
  std::string tool;                  // "fusion-import SUB", the name in usage errors
  std::string output, sensor_id;
  std::vector<std::string> inputs;
  fusion::clients::TumOptions tum;
  fusion::clients::Rosbag2Options rosbag2;
  fusion::v1::RecordedPose pose;  // --pose: sensor (pcd) or the --frame (scan) in the world
  bool pose_given = false, ignore_viewpoint = false, print_sensor = false;
  fusion::clients::PointFrame frame = fusion::clients::PointFrame::kOptical;  // scan, graph
  double start_time_s = 0, period_s = 1;  // stamps of pcd, graph and scan clouds
};

// argv[1]; returns the exit code when the tool is done already (no or an unknown subcommand,
// --help).
std::optional<int> ParseSubcommand(int argc, char** argv, Options* o) {
  if (argc < 2) {
    std::fputs(kUsage, stderr);
    return fusion::clients::kExitUsage;
  }
  o->sub = argv[1];
  if (fusion::clients::IsHelpFlag(o->sub) || o->sub == "help") {
    return fusion::clients::PrintHelp(kUsage);
  }
  if (o->sub == "tum") o->usage = kTumUsage, o->default_id = "tum";
  if (o->sub == "pcd") o->usage = kPcdUsage, o->default_id = "pcd";
  if (o->sub == "graph") o->usage = kGraphUsage, o->default_id = "scanner";
  if (o->sub == "scan") o->usage = kScanUsage, o->default_id = "scanner";
  if (o->sub == "rosbag2") o->usage = fusion::clients::kRosbag2Usage, o->default_id = "ros2";
  if (o->usage == nullptr) {
    std::fprintf(stderr, "fusion-import: unknown subcommand '%s'\n\n%s", o->sub.c_str(), kUsage);
    return fusion::clients::kExitUsage;
  }
  o->tool = "fusion-import " + o->sub;
  o->sensor_id = o->default_id;
  o->pose.set_qw(1.0);
  return std::nullopt;
}

// An option of `tum` with value `v`; false if `arg` is none.
bool ApplyTumValue(const std::string& arg, const std::string& v, fusion::clients::TumOptions* tum,
                   Status* s) {
  double* const number = arg == "--fx"            ? &tum->fx_px
                         : arg == "--fy"          ? &tum->fy_px
                         : arg == "--cx"          ? &tum->cx_px
                         : arg == "--cy"          ? &tum->cy_px
                         : arg == "--depth-scale" ? &tum->depth_scale
                                                  : nullptr;
  if (number != nullptr) {
    *s = fusion::clients::ParseDouble(arg, v, number);
  } else if (arg == "--stride") {
    std::uint64_t n = 0;
    *s = fusion::clients::ParseUint(arg, v, &n);
    tum->stride = static_cast<std::uint32_t>(n);
    if (s->ok() && (n == 0 || n > 640)) *s = Status::Error("--stride must be 1..640");
  } else if (arg == "--groundtruth") {
    tum->groundtruth = v;
  } else if (arg == "--max-frames") {
    *s = fusion::clients::ParseUint(arg, v, &tum->max_frames);
  } else {
    return false;
  }
  return true;
}

// An option with value `v`; false if the subcommand has no option `arg`.
bool ApplyValue(const std::string& arg, const std::string& v, Options* o, Status* s) {
  if (arg == "-o" || arg == "--output") {
    o->output = v;
  } else if (arg == "--sensor-id") {
    o->sensor_id = v;
  } else if (o->sub == "tum") {
    return ApplyTumValue(arg, v, &o->tum, s);
  } else if (o->sub == "rosbag2") {
    return fusion::clients::ApplyRosbag2Option(arg, v, &o->rosbag2, s);
  } else if ((o->sub == "pcd" || o->sub == "scan") && arg == "--pose") {
    *s = fusion::clients::ParsePose(arg, v, &o->pose);
    o->pose_given = true;
  } else if ((o->sub == "graph" || o->sub == "scan") && arg == "--frame") {
    *s = fusion::clients::ParsePointFrame(arg, v, &o->frame);
  } else if (arg == "--start-time") {
    *s = fusion::clients::ParseDouble(arg, v, &o->start_time_s);
  } else if (arg == "--period") {
    *s = fusion::clients::ParseDouble(arg, v, &o->period_s);
    if (s->ok() && o->period_s < 0) *s = Status::Error("--period must not be negative");
  } else {
    return false;
  }
  return true;
}

// The options after the subcommand; returns the exit code when the tool is done already.
std::optional<int> ParseOptions(int argc, char** argv, Options* o) {
  for (int i = 2; i < argc; ++i) {
    const std::string arg = argv[i];
    if (fusion::clients::IsHelpFlag(arg)) {
      PrintUsage(o->usage, o->default_id);
      return fusion::clients::kExitOk;
    }
    if (o->sub == "pcd" && arg == "--ignore-viewpoint") {
      o->ignore_viewpoint = true;
      continue;
    }
    if (arg == "--print-sensor") {
      o->print_sensor = true;
      continue;
    }
    if (arg.size() <= 1 || arg[0] != '-') {
      o->inputs.push_back(arg);
      continue;
    }
    // Every other option takes a value, known or not ("--bogus x" is one unknown option).
    std::string v;
    if (!fusion::clients::TakeValue(argc, argv, &i, &v)) {
      return fusion::clients::UsageError(o->tool, arg + " needs a value");
    }
    Status s;
    if (!ApplyValue(arg, v, o, &s)) {
      return fusion::clients::UsageError(o->tool, "unknown option " + arg);
    }
    if (!s.ok()) return fusion::clients::UsageError(o->tool, s.message());
  }
  if (o->output.empty()) return fusion::clients::UsageError(o->tool, "missing -o OUTPUT");
  if (o->inputs.empty()) return fusion::clients::UsageError(o->tool, "missing input");
  if ((o->sub == "tum" || o->sub == "graph" || o->sub == "rosbag2") && o->inputs.size() != 1) {
    return fusion::clients::UsageError(o->tool, "expects exactly one input");
  }
  if (o->sensor_id.empty())
    return fusion::clients::UsageError(o->tool, "--sensor-id must not be empty");
  if (o->sub == "rosbag2") {
    o->rosbag2.bag = o->inputs[0];
    o->rosbag2.sensor_id = o->sensor_id;
    if (Status s = fusion::clients::CheckRosbag2Options(o->rosbag2); !s.ok()) {
      return fusion::clients::UsageError(o->tool, s.message());
    }
  }
  return std::nullopt;
}

// Appends the imported clouds to the recording, numbering and stamping those the importer
// leaves without identity (all but TUM's).
class Sink {
 public:
  Sink(const Options& o, fusion::clients::RecordingWriter* writer) : o_(o), writer_(writer) {}
  std::uint64_t points() const { return points_; }
  // What --print-sensor describes: every cloud appended (but TUM's).
  const fusion::clients::ImportedGeometry& geometry() const { return geometry_; }

  // Sensor id, sequence number from 1, stamp start_time + period x (number - 1).
  void Identify(fusion::v1::RecordedCloud* cloud, const std::string& origin) {
    fusion::clients::SetIdentity(o_.sensor_id, sequence_ + 1,
                                 o_.start_time_s + o_.period_s * sequence_, origin, cloud);
    ++sequence_;
  }

  Status Append(fusion::v1::RecordedCloud&& cloud) {
    points_ += cloud.xyz_f32le().size() / 12;
    if (o_.print_sensor && o_.sub != "tum") geometry_.Add(cloud);  // TUM's: its options
    Status s = writer_->Append(cloud);
    if (s.ok() && tty_) {
      std::fprintf(stderr, "\rfusion-import: %llu clouds",
                   static_cast<unsigned long long>(writer_->records_written()));
    }
    return s;
  }

 private:
  const Options& o_;
  fusion::clients::RecordingWriter* const writer_;
  const bool tty_ = isatty(STDERR_FILENO) != 0;  // a running count on a terminal
  std::uint64_t points_ = 0, sequence_ = 0;
  fusion::clients::ImportedGeometry geometry_;
};

Status ImportPcdFiles(const Options& o, Sink* sink) {
  for (const auto& path : o.inputs) {
    fusion::v1::RecordedCloud cloud;
    if (Status s = fusion::clients::ReadPcd(path, &cloud, !o.ignore_viewpoint); !s.ok()) return s;
    if (const double behind = fusion::clients::FractionBehindSensor(cloud); behind > 0.5) {
      std::fprintf(stderr,
                   "fusion-import: warning: %s: %.0f%% of the points lie behind the sensor "
                   "(z < 0)%s\n",
                   path.c_str(), 100 * behind,
                   o.ignore_viewpoint ? "" : "; if its VIEWPOINT is wrong, use --ignore-viewpoint");
    }
    if (o.pose_given) {
      const auto& T = cloud.t_world_sensor();
      if (!(T.tx() == 0 && T.ty() == 0 && T.tz() == 0 && T.qw() == 1.0)) {
        return Status::Error(path + ": has a non-identity VIEWPOINT; drop --pose to use it");
      }
      *cloud.mutable_t_world_sensor() = o.pose;
    }
    sink->Identify(&cloud, path);
    if (Status s = sink->Append(std::move(cloud)); !s.ok()) return s;
  }
  return Status::Ok();
}

// graph and scan: several clouds a file.
Status ImportMultiCloudFiles(const Options& o, Sink* sink) {
  for (const auto& path : o.inputs) {
    std::vector<fusion::v1::RecordedCloud> clouds;
    Status s = o.sub == "graph" ? fusion::clients::ReadScanGraph(path, &clouds)
                                : fusion::clients::ReadXyzScan(path, o.pose, &clouds);
    if (!s.ok()) return s;
    for (auto& cloud : clouds) {
      fusion::clients::ToOpticalFrame(o.frame, &cloud);
      sink->Identify(&cloud, path);
      if (s = sink->Append(std::move(cloud)); !s.ok()) return s;
    }
  }
  return Status::Ok();
}

// rosbag2: one bag; progress, skips and notes on stderr.
Status ImportBag(Options* o, Sink* sink) {
  o->rosbag2.progress = stderr;
  return fusion::clients::ImportRosbag2(o->rosbag2, [sink](fusion::v1::RecordedCloud&& cloud) {
    return sink->Append(std::move(cloud));
  });
}

// *image: the size of TUM's depth images.
Status Import(Options* o, Sink* sink, fusion::clients::ImageSize* image) {
  if (o->sub == "tum") {
    o->tum.directory = o->inputs[0];
    o->tum.sensor_id = o->sensor_id;
    return fusion::clients::ImportTum(
        o->tum,
        [sink](fusion::v1::RecordedCloud&& cloud) { return sink->Append(std::move(cloud)); },
        image);
  }
  if (o->sub == "pcd") return ImportPcdFiles(*o, sink);
  if (o->sub == "rosbag2") return ImportBag(o, sink);
  return ImportMultiCloudFiles(*o, sink);
}

// --print-sensor: the block on stdout, notes on stderr.
Status PrintSensor(const Options& o, const Sink& sink, const fusion::clients::ImageSize& image) {
  fusion::v1::SensorConfig sensor;
  std::string notes;
  if (o.sub == "tum") {
    sensor = fusion::clients::TumSensorConfig(o.tum, image);
  } else if (Status s = sink.geometry().Describe(
                 o.sensor_id, o.sub == "pcd" || o.sub == "rosbag2" ? "" : "laser_3d", &sensor,
                 &notes);
             !s.ok()) {
    return Status::Error("--print-sensor: " + s.message());
  }
  std::istringstream lines(notes);
  for (std::string line; std::getline(lines, line);) {
    std::fprintf(stderr, "fusion-import: %s\n", line.c_str());
  }
  std::fputs(fusion::clients::SensorBlockText(sensor).c_str(), stdout);
  return Status::Ok();
}

}  // namespace

int main(int argc, char** argv) {
  Options o;
  if (const auto done = ParseSubcommand(argc, argv, &o)) return *done;
  if (const auto done = ParseOptions(argc, argv, &o)) return *done;

  std::string source = o.sub + ":";
  for (const auto& in : o.inputs) source += " " + in;
  std::unique_ptr<fusion::clients::RecordingWriter> writer;
  if (Status s = fusion::clients::RecordingWriter::Create(o.output, o.tool, source, &writer);
      !s.ok()) {
    return fusion::clients::Fail(kTool, s.message());
  }
  Sink sink(o, writer.get());
  fusion::clients::ImageSize image;
  const Status status = Import(&o, &sink, &image);
  if (isatty(STDERR_FILENO) != 0 && writer->records_written() > 0) std::fputc('\n', stderr);
  const Status closed = writer->Close();
  if (!status.ok() && writer->records_written() == 0) {
    std::remove(o.output.c_str());  // nothing worth keeping
    return fusion::clients::Fail(kTool, status.message());
  }
  if (!status.ok()) {
    fusion::clients::Fail(kTool, status.message());
    return fusion::clients::Fail(kTool, o.output + " keeps the " +
                                            std::to_string(writer->records_written()) +
                                            " clouds imported before the error");
  }
  if (!closed.ok()) return fusion::clients::Fail(kTool, closed.message());
  std::fprintf(o.print_sensor ? stderr : stdout, "%simported %llu clouds (%llu points) into %s\n",
               o.print_sensor ? "fusion-import: " : "",
               static_cast<unsigned long long>(writer->records_written()),
               static_cast<unsigned long long>(sink.points()), o.output.c_str());
  if (o.print_sensor) {
    if (Status s = PrintSensor(o, sink, image); !s.ok())
      return fusion::clients::Fail(kTool, s.message());
  }
  return fusion::clients::kExitOk;
}
