// fusion-replay: publishes a recording on the point-cloud topic, at the original pace or faster.
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <memory>
#include <string>
#include <thread>

#include "fusion/clients/cli.h"
#include "fusion/clients/crc32.h"
#include "fusion/clients/dds_io.h"
#include "fusion/clients/recording.h"

namespace {

using fusion::clients::Status;
using Clock = std::chrono::steady_clock;

constexpr const char* kUsage = R"(fusion-replay: publish a recording on the DDS bus

Usage: fusion-replay RECORDING.frec [options]
       fusion-replay --list RECORDING.frec
  --domain N          DDS domain id (default 0)
  --topic NAME        topic (default fusion/points)
  --fast              publish as fast as possible (default: the recorded pace)
  --rate X            pace multiplier: 2 = twice as fast (default 1)
  --loop              start again at the end until interrupted; sequence numbers keep
                      increasing from loop to loop
  --restamp           stamp every cloud with the time it is published
  --reliable          reliable, keep-all writer: waits for slow readers instead of dropping
  --wait-readers N    wait for N matched readers before publishing (default 1)
  --wait-timeout S    how long to wait for them (default 10; then publish anyway)
  --quiet             no progress output
  --list              print one line per record (checking each record's CRC) and exit
  --help              this text

Progress goes to stderr: a bar on a terminal, a line every 5 s otherwise. A broken record
("record 17 at byte 123456: crc mismatch") ends the replay after everything before it was
published; the exit status is then 1.
Transport: CYCLONEDDS_URI if set, else a loopback-only configuration.
)";

std::atomic<bool> g_stop{false};
void OnSignal(int) { g_stop = true; }

int UsageError(const std::string& message) {
  std::fprintf(stderr, "fusion-replay: %s (see fusion-replay --help)\n", message.c_str());
  return 2;
}

std::string Describe(std::size_t i, const fusion::v1::RecordedCloud& c) {
  char text[512];
  const auto& T = c.t_world_sensor();
  std::snprintf(text, sizeof text,
                "%zu sensor=%s seq=%llu stamp=%d.%09u size=%ux%u pose=%.6f,%.6f,%.6f,%.6f,%.6f,"
                "%.6f,%.6f xyz_crc32=%08x beyond_range=%zu",
                i, c.sensor_id().c_str(), static_cast<unsigned long long>(c.sequence_number()),
                c.stamp().sec(), c.stamp().nanosec(), c.width(), c.height(), T.tx(), T.ty(), T.tz(),
                T.qx(), T.qy(), T.qz(), T.qw(),
                fusion::clients::Crc32(c.xyz_f32le().data(), c.xyz_f32le().size()),
                c.beyond_range().size());
  return text;
}

int List(const std::string& path) {
  std::unique_ptr<fusion::clients::RecordingReader> reader;
  if (Status s = fusion::clients::RecordingReader::Open(path, &reader); !s.ok()) {
    std::fprintf(stderr, "fusion-replay: %s\n", s.message().c_str());
    return 1;
  }
  std::printf("# %s: written by '%s' from '%s', %zu records, %s\n", path.c_str(),
              reader->header().writer().c_str(), reader->header().source().c_str(), reader->size(),
              reader->indexed() ? "indexed" : reader->index_note().c_str());
  fusion::v1::RecordedCloud cloud;
  for (std::size_t i = 0; i < reader->size(); ++i) {
    if (Status s = reader->Read(i, &cloud); !s.ok()) {
      std::fprintf(stderr, "fusion-replay: %s: %s\n", path.c_str(), s.message().c_str());
      return 1;
    }
    std::printf("%s\n", Describe(i, cloud).c_str());
  }
  if (!reader->tail_error().ok()) {
    std::fprintf(stderr, "fusion-replay: %s: %s\n", path.c_str(),
                 reader->tail_error().message().c_str());
    return 1;
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  std::string path, topic = fusion::clients::kPointsTopic;
  std::uint64_t domain = 0, wait_readers = 1;
  double rate = 1.0, wait_timeout_s = 10;
  bool fast = false, loop = false, restamp = false, quiet = false, list = false;
  fusion::clients::PointsQos qos;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    std::string v;
    Status s;
    if (arg == "--help" || arg == "-h") {
      std::fputs(kUsage, stdout);
      return 0;
    } else if (arg == "--fast") {
      fast = true;
    } else if (arg == "--loop") {
      loop = true;
    } else if (arg == "--restamp") {
      restamp = true;
    } else if (arg == "--reliable") {
      qos.reliable = true;
    } else if (arg == "--quiet") {
      quiet = true;
    } else if (arg == "--list") {
      list = true;
    } else if (arg == "--domain" || arg == "--topic" || arg == "--rate" ||
               arg == "--wait-readers" || arg == "--wait-timeout") {
      if (i + 1 >= argc) return UsageError(arg + " needs a value");
      v = argv[++i];
      if (arg == "--topic") topic = v;
      if (arg == "--domain") {
        s = fusion::clients::ParseUint(arg, v, &domain);
        if (s.ok() && domain > 230) s = Status::Error("--domain must be 0..230");
      }
      if (arg == "--wait-readers") s = fusion::clients::ParseUint(arg, v, &wait_readers);
      if (arg == "--rate") {
        s = fusion::clients::ParseDouble(arg, v, &rate);
        if (s.ok() && rate <= 0) s = Status::Error("--rate must be positive");
      }
      if (arg == "--wait-timeout") {
        s = fusion::clients::ParseDouble(arg, v, &wait_timeout_s);
        if (s.ok() && wait_timeout_s < 0) s = Status::Error("--wait-timeout must not be negative");
      }
    } else if (!arg.empty() && arg[0] == '-') {
      return UsageError("unknown option " + arg);
    } else if (path.empty()) {
      path = arg;
    } else {
      return UsageError("more than one recording given");
    }
    if (!s.ok()) return UsageError(s.message());
  }
  if (path.empty()) return UsageError("missing RECORDING");
  if (list) return List(path);

  std::unique_ptr<fusion::clients::RecordingReader> reader;
  if (Status s = fusion::clients::RecordingReader::Open(path, &reader); !s.ok()) {
    std::fprintf(stderr, "fusion-replay: %s\n", s.message().c_str());
    return 1;
  }
  if (!reader->indexed()) {
    std::fprintf(stderr, "fusion-replay: %s: %s; read sequentially (%zu records)\n", path.c_str(),
                 reader->index_note().c_str(), reader->size());
  }
  const std::size_t total = reader->size();
  if (total == 0) {
    std::fprintf(stderr, "fusion-replay: %s has no records\n", path.c_str());
    return reader->tail_error().ok() ? 0 : 1;
  }

  std::signal(SIGINT, OnSignal);
  std::signal(SIGTERM, OnSignal);
  std::unique_ptr<fusion::clients::PointCloudWriter> writer;
  if (Status s = fusion::clients::PointCloudWriter::Create(static_cast<std::uint32_t>(domain),
                                                           topic, qos, &writer);
      !s.ok()) {
    std::fprintf(stderr, "fusion-replay: cannot publish: %s\n", s.message().c_str());
    return 1;
  }
  if (wait_readers > 0 && !writer->WaitForReaders(static_cast<std::uint32_t>(wait_readers),
                                                  std::chrono::milliseconds(
                                                      static_cast<long>(wait_timeout_s * 1000)))) {
    std::fprintf(stderr, "fusion-replay: only %u of %llu readers after %.1f s; publishing anyway\n",
                 writer->matched_readers(), static_cast<unsigned long long>(wait_readers),
                 wait_timeout_s);
  }
  std::printf("fusion-replay: publishing %zu clouds from %s on %s in domain %llu\n", total,
              path.c_str(), topic.c_str(), static_cast<unsigned long long>(domain));
  std::fflush(stdout);

  // Pace by the receive times when the recording has them, else by the stamps.
  bool have_receive_times = true;
  std::uint64_t max_sequence = 0;
  for (std::size_t i = 0; i < total; ++i) {
    have_receive_times = have_receive_times && reader->entry(i).receive_time_unix_ns() != 0;
    max_sequence = std::max(max_sequence, reader->entry(i).sequence_number());
  }
  const auto record_time_s = [&](std::size_t i) {
    const auto& e = reader->entry(i);
    return have_receive_times ? 1e-9 * static_cast<double>(e.receive_time_unix_ns())
                              : fusion::clients::SecondsFromTime(e.stamp());
  };

  const bool tty = isatty(STDERR_FILENO) != 0;
  const auto start = Clock::now();
  auto last_progress = start - std::chrono::seconds(10);
  std::uint64_t published = 0;
  Status broken;
  const auto progress = [&](std::size_t done, std::uint64_t loop_index, bool final_line) {
    const double elapsed_s = std::chrono::duration<double>(Clock::now() - start).count();
    if (tty) {
      constexpr int kBarWidth = 30;
      const int filled = static_cast<int>(kBarWidth * done / total);
      std::string bar(static_cast<std::size_t>(filled), '#');
      bar.resize(kBarWidth, '.');
      std::fprintf(stderr, "\r[%s] %zu/%zu clouds%s  %.1f s%s", bar.c_str(), done, total,
                   loop ? (" loop " + std::to_string(loop_index + 1)).c_str() : "", elapsed_s,
                   final_line ? "\n" : "");
    } else {
      std::fprintf(stderr, "fusion-replay: %zu/%zu clouds%s, %.1f s\n", done, total,
                   loop ? (" (loop " + std::to_string(loop_index + 1) + ")").c_str() : "",
                   elapsed_s);
    }
  };

  fusion::v1::RecordedCloud cloud;
  std::uint64_t loop_index = 0;
  for (; !g_stop; ++loop_index) {
    const auto loop_start = Clock::now();
    const double t0_s = record_time_s(0);
    for (std::size_t i = 0; i < total && !g_stop; ++i) {
      if (!fast) {
        const double offset_s = std::max(0.0, (record_time_s(i) - t0_s) / rate);
        const auto due = loop_start + std::chrono::duration_cast<Clock::duration>(
                                          std::chrono::duration<double>(offset_s));
        while (!g_stop && Clock::now() < due) {
          std::this_thread::sleep_until(
              std::min(due, Clock::now() + std::chrono::milliseconds(100)));
        }
        if (g_stop) break;
      }
      if (Status s = reader->Read(i, &cloud); !s.ok()) {
        broken = s;
        break;
      }
      cloud.set_sequence_number(cloud.sequence_number() + loop_index * (max_sequence + 1));
      if (restamp) {
        const std::int64_t now_ns = fusion::clients::UnixNowNs();
        cloud.mutable_stamp()->set_sec(static_cast<std::int32_t>(now_ns / 1000000000));
        cloud.mutable_stamp()->set_nanosec(static_cast<std::uint32_t>(now_ns % 1000000000));
      }
      if (Status s = writer->Write(cloud); !s.ok()) {
        std::fprintf(stderr, "\nfusion-replay: %s\n", s.message().c_str());
        return 1;
      }
      ++published;
      const auto now = Clock::now();
      if (!quiet && now - last_progress >=
                        (tty ? std::chrono::milliseconds(100) : std::chrono::milliseconds(5000))) {
        progress(i + 1, loop_index, false);
        last_progress = now;
      }
      if (i + 1 == total && !quiet) progress(total, loop_index, !loop);
    }
    if (!broken.ok() || !loop) break;
    if (!reader->tail_error().ok()) break;
  }
  if (qos.reliable) {
    if (Status s = writer->WaitForAcks(std::chrono::seconds(30)); !s.ok()) {
      std::fprintf(stderr, "fusion-replay: not every reader acknowledged: %s\n",
                   s.message().c_str());
    }
  }
  if (tty && !quiet && (g_stop || !broken.ok())) std::fputc('\n', stderr);
  if (broken.ok() && !reader->tail_error().ok()) broken = reader->tail_error();
  if (!broken.ok()) {
    std::fprintf(stderr, "fusion-replay: %s: %s; stopped after publishing %llu clouds\n",
                 path.c_str(), broken.message().c_str(),
                 static_cast<unsigned long long>(published));
    return 1;
  }
  std::printf("fusion-replay: published %llu clouds\n", static_cast<unsigned long long>(published));
  return 0;
}
