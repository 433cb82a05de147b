// fusion-record: subscribes to the point-cloud topic and writes every cloud to a recording.
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "fusion/clients/cli.h"
#include "fusion/clients/dds_io.h"
#include "fusion/clients/recording.h"

namespace {

using fusion::Status;
using Clock = std::chrono::steady_clock;

constexpr const char* kTool = "fusion-record";

constexpr const char* kUsage =
    R"(fusion-record: write the clouds published on the DDS bus to a recording

Usage: fusion-record -o OUTPUT.frec [options]
  -o, --output FILE   recording to write (created or truncated)
  --domain N          DDS domain id (default 0)
  --topic NAME        topic (default fusion/points)
  --reliable          reliable, keep-all reader: matches reliable writers (e.g. fusion-replay
                      --reliable) and loses nothing; best-effort writers are then not matched
  --depth N           best-effort history depth per sensor (default 8)
  --count N           stop after N clouds
  --duration S        stop after S seconds
  --sensor ID         record only this sensor (repeatable)
  --quiet             no progress line
  --help              this text

Stops on SIGINT or SIGTERM, or after --count/--duration, and then writes the index. If the
process dies instead, every cloud written so far still replays (the index is optional).
Transport: CYCLONEDDS_URI if set, else a loopback-only configuration.
)";

struct Options {
  std::string output, topic = fusion::clients::kPointsTopic;
  std::uint64_t domain = 0, count = 0, depth = 8;  // count 0 = no limit
  double duration_s = 0;                           // 0 = no limit
  bool quiet = false;
  fusion::clients::PointsQos qos;
  std::vector<std::string> sensors;  // empty = every sensor
};

// The option `arg` that takes value `v`.
Status ApplyValue(const std::string& arg, const std::string& v, Options* o) {
  Status s;
  if (arg == "-o" || arg == "--output") o->output = v;
  if (arg == "--topic") o->topic = v;
  if (arg == "--sensor") o->sensors.push_back(v);
  if (arg == "--domain") s = fusion::clients::ParseDomain(arg, v, &o->domain);
  if (arg == "--count") s = fusion::clients::ParseUint(arg, v, &o->count);
  if (arg == "--depth") {
    s = fusion::clients::ParseUint(arg, v, &o->depth);
    if (s.ok() && (o->depth == 0 || o->depth > 10000))
      s = Status::Error("--depth must be 1..10000");
  }
  if (arg == "--duration") {
    s = fusion::clients::ParseDouble(arg, v, &o->duration_s);
    if (s.ok() && o->duration_s <= 0) s = Status::Error("--duration must be positive");
  }
  return s;
}

// Returns the exit code when the tool is done already (--help, a bad command line).
std::optional<int> ParseFlags(int argc, char** argv, Options* o) {
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    std::string v;
    Status s;
    if (fusion::clients::IsHelpFlag(arg)) {
      return fusion::clients::PrintHelp(kUsage);
    } else if (arg == "--reliable") {
      o->qos.reliable = true;
    } else if (arg == "--quiet") {
      o->quiet = true;
    } else if (arg == "-o" || arg == "--output" || arg == "--domain" || arg == "--topic" ||
               arg == "--count" || arg == "--duration" || arg == "--sensor" || arg == "--depth") {
      if (!fusion::clients::TakeValue(argc, argv, &i, &v)) {
        return fusion::clients::UsageError(kTool, arg + " needs a value");
      }
      s = ApplyValue(arg, v, o);
    } else {
      return fusion::clients::UsageError(kTool, "unknown argument " + arg);
    }
    if (!s.ok()) return fusion::clients::UsageError(kTool, s.message());
  }
  if (o->output.empty()) return fusion::clients::UsageError(kTool, "missing -o OUTPUT");
  o->qos.depth = static_cast<std::int32_t>(o->depth);
  return std::nullopt;
}

// "recorded N clouds, ..." on stderr: rewritten in place on a terminal, a line otherwise.
void PrintProgress(const fusion::clients::RecordingWriter& writer, Clock::time_point start,
                   bool tty, bool final_line) {
  const double elapsed_s = std::chrono::duration<double>(Clock::now() - start).count();
  std::fprintf(stderr, "%srecorded %llu clouds, %.1f MB in %.1f s (%.1f clouds/s)%s",
               tty ? "\r" : "", static_cast<unsigned long long>(writer.records_written()),
               writer.bytes_written() / 1e6, elapsed_s,
               elapsed_s > 0 ? writer.records_written() / elapsed_s : 0.0,
               tty && !final_line ? "" : "\n");
}

// Takes clouds until a stop request, --count or --duration; *skipped counts the clouds of
// sensors not asked for. Returns the first read or write error.
Status Record(const Options& o, fusion::clients::PointCloudReader* reader,
              fusion::clients::RecordingWriter* writer, std::uint64_t* skipped) {
  const bool tty = isatty(STDERR_FILENO) != 0;
  const auto start = Clock::now();
  auto last_progress = start;
  Status status;
  std::vector<fusion::v1::RecordedCloud> clouds;
  while (!fusion::clients::StopRequested()) {
    const auto now = Clock::now();
    if (o.duration_s > 0 && std::chrono::duration<double>(now - start).count() >= o.duration_s) {
      break;
    }
    if (o.count > 0 && writer->records_written() >= o.count) break;
    clouds.clear();
    status = reader->Take(std::chrono::milliseconds(100), &clouds);
    if (!status.ok()) break;
    for (const auto& cloud : clouds) {
      if (o.count > 0 && writer->records_written() >= o.count) break;
      if (!o.sensors.empty() &&
          std::find(o.sensors.begin(), o.sensors.end(), cloud.sensor_id()) == o.sensors.end()) {
        ++*skipped;
        continue;
      }
      status = writer->Append(cloud);
      if (!status.ok()) break;
    }
    if (!status.ok()) break;
    if (!o.quiet && now - last_progress >= std::chrono::seconds(tty ? 0 : 5) &&
        now - last_progress >= std::chrono::milliseconds(200)) {
      PrintProgress(*writer, start, tty, false);
      last_progress = now;
    }
  }
  if (!o.quiet) PrintProgress(*writer, start, tty, true);
  return status;
}

}  // namespace

int main(int argc, char** argv) {
  Options o;
  if (const auto done = ParseFlags(argc, argv, &o)) return *done;
  fusion::clients::InstallStopHandlers();

  std::unique_ptr<fusion::clients::PointCloudReader> reader;
  if (Status s = fusion::clients::PointCloudReader::Create(static_cast<std::uint32_t>(o.domain),
                                                           o.topic, o.qos, &reader);
      !s.ok()) {
    return fusion::clients::Fail(kTool, "cannot subscribe: " + s.message());
  }
  const std::string source = "dds: domain " + std::to_string(o.domain) + " topic " + o.topic +
                             (o.qos.reliable ? " (reliable)" : " (best effort)");
  std::unique_ptr<fusion::clients::RecordingWriter> writer;
  if (Status s = fusion::clients::RecordingWriter::Create(o.output, kTool, source, &writer);
      !s.ok()) {
    return fusion::clients::Fail(kTool, s.message());
  }
  std::printf("fusion-record: subscribed to %s in domain %llu, writing %s\n", o.topic.c_str(),
              static_cast<unsigned long long>(o.domain), o.output.c_str());
  std::fflush(stdout);

  std::uint64_t skipped = 0;
  const Status status = Record(o, reader.get(), writer.get(), &skipped);
  const Status closed = writer->Close();
  if (!status.ok()) return fusion::clients::Fail(kTool, status.message());
  if (!closed.ok()) return fusion::clients::Fail(kTool, closed.message());
  std::printf(
      "fusion-record: recorded %llu clouds to %s%s\n",
      static_cast<unsigned long long>(writer->records_written()), o.output.c_str(),
      skipped ? (" (" + std::to_string(skipped) + " of other sensors skipped)").c_str() : "");
  return fusion::clients::kExitOk;
}
