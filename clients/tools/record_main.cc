// fusion-record: subscribes to the point-cloud topic and writes every cloud to a recording.
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include "fusion/clients/cli.h"
#include "fusion/clients/dds_io.h"
#include "fusion/clients/recording.h"

namespace {

using fusion::clients::Status;

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

std::atomic<bool> g_stop{false};
void OnSignal(int) { g_stop = true; }

int UsageError(const std::string& message) {
  std::fprintf(stderr, "fusion-record: %s (see fusion-record --help)\n", message.c_str());
  return 2;
}

}  // namespace

int main(int argc, char** argv) {
  std::string output, topic = fusion::clients::kPointsTopic;
  std::uint64_t domain = 0, count = 0, depth = 8;
  double duration_s = 0;
  bool quiet = false;
  fusion::clients::PointsQos qos;
  std::vector<std::string> sensors;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    std::string v;
    const auto value = [&]() {
      if (i + 1 >= argc) return false;
      v = argv[++i];
      return true;
    };
    Status s;
    if (arg == "--help" || arg == "-h") {
      std::fputs(kUsage, stdout);
      return 0;
    } else if (arg == "--reliable") {
      qos.reliable = true;
    } else if (arg == "--quiet") {
      quiet = true;
    } else if (arg == "-o" || arg == "--output" || arg == "--domain" || arg == "--topic" ||
               arg == "--count" || arg == "--duration" || arg == "--sensor" || arg == "--depth") {
      if (!value()) return UsageError(arg + " needs a value");
      if (arg == "-o" || arg == "--output") output = v;
      if (arg == "--topic") topic = v;
      if (arg == "--sensor") sensors.push_back(v);
      if (arg == "--domain") {
        s = fusion::clients::ParseUint(arg, v, &domain);
        if (s.ok() && domain > 230) s = Status::Error("--domain must be 0..230");
      }
      if (arg == "--count") s = fusion::clients::ParseUint(arg, v, &count);
      if (arg == "--depth") {
        s = fusion::clients::ParseUint(arg, v, &depth);
        if (s.ok() && (depth == 0 || depth > 10000)) s = Status::Error("--depth must be 1..10000");
      }
      if (arg == "--duration") {
        s = fusion::clients::ParseDouble(arg, v, &duration_s);
        if (s.ok() && duration_s <= 0) s = Status::Error("--duration must be positive");
      }
    } else {
      return UsageError("unknown argument " + arg);
    }
    if (!s.ok()) return UsageError(s.message());
  }
  if (output.empty()) return UsageError("missing -o OUTPUT");
  qos.depth = static_cast<std::int32_t>(depth);

  std::signal(SIGINT, OnSignal);
  std::signal(SIGTERM, OnSignal);

  std::unique_ptr<fusion::clients::PointCloudReader> reader;
  if (Status s = fusion::clients::PointCloudReader::Create(static_cast<std::uint32_t>(domain),
                                                           topic, qos, &reader);
      !s.ok()) {
    std::fprintf(stderr, "fusion-record: cannot subscribe: %s\n", s.message().c_str());
    return 1;
  }
  const std::string source = "dds: domain " + std::to_string(domain) + " topic " + topic +
                             (qos.reliable ? " (reliable)" : " (best effort)");
  std::unique_ptr<fusion::clients::RecordingWriter> writer;
  if (Status s = fusion::clients::RecordingWriter::Create(output, "fusion-record", source, &writer);
      !s.ok()) {
    std::fprintf(stderr, "fusion-record: %s\n", s.message().c_str());
    return 1;
  }
  std::printf("fusion-record: subscribed to %s in domain %llu, writing %s\n", topic.c_str(),
              static_cast<unsigned long long>(domain), output.c_str());
  std::fflush(stdout);

  const bool tty = isatty(STDERR_FILENO) != 0;
  const auto start = std::chrono::steady_clock::now();
  auto last_progress = start;
  std::uint64_t skipped = 0;
  Status status;
  std::vector<fusion::v1::RecordedCloud> clouds;
  const auto progress = [&](bool final_line) {
    const double elapsed_s =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    std::fprintf(stderr, "%srecorded %llu clouds, %.1f MB in %.1f s (%.1f clouds/s)%s",
                 tty ? "\r" : "", static_cast<unsigned long long>(writer->records_written()),
                 writer->bytes_written() / 1e6, elapsed_s,
                 elapsed_s > 0 ? writer->records_written() / elapsed_s : 0.0,
                 tty && !final_line ? "" : "\n");
  };
  while (!g_stop) {
    const auto now = std::chrono::steady_clock::now();
    if (duration_s > 0 && std::chrono::duration<double>(now - start).count() >= duration_s) break;
    if (count > 0 && writer->records_written() >= count) break;
    clouds.clear();
    status = reader->Take(std::chrono::milliseconds(100), &clouds);
    if (!status.ok()) break;
    for (const auto& cloud : clouds) {
      if (count > 0 && writer->records_written() >= count) break;
      if (!sensors.empty() &&
          std::find(sensors.begin(), sensors.end(), cloud.sensor_id()) == sensors.end()) {
        ++skipped;
        continue;
      }
      status = writer->Append(cloud);
      if (!status.ok()) break;
    }
    if (!status.ok()) break;
    if (!quiet && now - last_progress >= std::chrono::seconds(tty ? 0 : 5) &&
        now - last_progress >= std::chrono::milliseconds(200)) {
      progress(false);
      last_progress = now;
    }
  }
  if (!quiet) progress(true);
  const Status closed = writer->Close();
  if (!status.ok()) {
    std::fprintf(stderr, "fusion-record: %s\n", status.message().c_str());
    return 1;
  }
  if (!closed.ok()) {
    std::fprintf(stderr, "fusion-record: %s\n", closed.message().c_str());
    return 1;
  }
  std::printf(
      "fusion-record: recorded %llu clouds to %s%s\n",
      static_cast<unsigned long long>(writer->records_written()), output.c_str(),
      skipped ? (" (" + std::to_string(skipped) + " of other sensors skipped)").c_str() : "");
  return 0;
}
