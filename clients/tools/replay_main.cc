// fusion-replay: publishes a recording on the point-cloud topic, at the original pace or faster.
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <memory>
#include <optional>
#include <string>

#include "fusion/clients/cli.h"
#include "fusion/clients/crc32.h"
#include "fusion/clients/dds_io.h"
#include "fusion/clients/recording.h"

namespace {

using fusion::Status;
using Clock = std::chrono::steady_clock;

constexpr const char* kTool = "fusion-replay";

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
    return fusion::clients::Fail(kTool, s.message());
  }
  std::printf("# %s: written by '%s' from '%s', %zu records, %s\n", path.c_str(),
              reader->header().writer().c_str(), reader->header().source().c_str(), reader->size(),
              reader->indexed() ? "indexed" : reader->index_note().c_str());
  fusion::v1::RecordedCloud cloud;
  for (std::size_t i = 0; i < reader->size(); ++i) {
    if (Status s = reader->Read(i, &cloud); !s.ok()) {
      return fusion::clients::Fail(kTool, path + ": " + s.message());
    }
    std::printf("%s\n", Describe(i, cloud).c_str());
  }
  if (!reader->tail_error().ok()) {
    return fusion::clients::Fail(kTool, path + ": " + reader->tail_error().message());
  }
  return fusion::clients::kExitOk;
}

struct Options {
  std::string path, topic = fusion::clients::kPointsTopic;
  std::uint64_t domain = 0, wait_readers = 1;
  double rate = 1.0, wait_timeout_s = 10;  // rate: pace multiplier
  bool fast = false, loop = false, restamp = false, quiet = false, list = false;
  fusion::clients::PointsQos qos;
};

// The option `arg` that takes value `v`.
Status ApplyValue(const std::string& arg, const std::string& v, Options* o) {
  Status s;
  if (arg == "--topic") o->topic = v;
  if (arg == "--domain") s = fusion::clients::ParseDomain(arg, v, &o->domain);
  if (arg == "--wait-readers") s = fusion::clients::ParseUint(arg, v, &o->wait_readers);
  if (arg == "--rate") {
    s = fusion::clients::ParseDouble(arg, v, &o->rate);
    if (s.ok() && o->rate <= 0) s = Status::Error("--rate must be positive");
  }
  if (arg == "--wait-timeout") {
    s = fusion::clients::ParseDouble(arg, v, &o->wait_timeout_s);
    if (s.ok() && o->wait_timeout_s < 0) s = Status::Error("--wait-timeout must not be negative");
  }
  return s;
}

// A flag without a value; false if `arg` is none.
bool ApplyFlag(const std::string& arg, Options* o) {
  bool* const flag = arg == "--fast"       ? &o->fast
                     : arg == "--loop"     ? &o->loop
                     : arg == "--restamp"  ? &o->restamp
                     : arg == "--reliable" ? &o->qos.reliable
                     : arg == "--quiet"    ? &o->quiet
                     : arg == "--list"     ? &o->list
                                           : nullptr;
  if (flag != nullptr) *flag = true;
  return flag != nullptr;
}

// Returns the exit code when the tool is done already (--help, a bad command line).
std::optional<int> ParseFlags(int argc, char** argv, Options* o) {
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    std::string v;
    Status s;
    if (fusion::clients::IsHelpFlag(arg)) return fusion::clients::PrintHelp(kUsage);
    if (ApplyFlag(arg, o)) continue;
    if (arg == "--domain" || arg == "--topic" || arg == "--rate" || arg == "--wait-readers" ||
        arg == "--wait-timeout") {
      if (!fusion::clients::TakeValue(argc, argv, &i, &v)) {
        return fusion::clients::UsageError(kTool, arg + " needs a value");
      }
      s = ApplyValue(arg, v, o);
    } else if (!arg.empty() && arg[0] == '-') {
      return fusion::clients::UsageError(kTool, "unknown option " + arg);
    } else if (o->path.empty()) {
      o->path = arg;
    } else {
      return fusion::clients::UsageError(kTool, "more than one recording given");
    }
    if (!s.ok()) return fusion::clients::UsageError(kTool, s.message());
  }
  if (o->path.empty()) return fusion::clients::UsageError(kTool, "missing RECORDING");
  return std::nullopt;
}

// The writer, once the readers asked for have matched (or the wait timed out).
Status CreateWriter(const Options& o, std::unique_ptr<fusion::clients::PointCloudWriter>* writer) {
  if (Status s = fusion::clients::PointCloudWriter::Create(static_cast<std::uint32_t>(o.domain),
                                                           o.topic, o.qos, writer);
      !s.ok()) {
    return Status::Error("cannot publish: " + s.message());
  }
  const auto timeout = std::chrono::milliseconds(static_cast<long>(o.wait_timeout_s * 1000));
  if (o.wait_readers > 0 &&
      !(*writer)->WaitForReaders(static_cast<std::uint32_t>(o.wait_readers), timeout)) {
    std::fprintf(stderr, "fusion-replay: only %u of %llu readers after %.1f s; publishing anyway\n",
                 (*writer)->matched_readers(), static_cast<unsigned long long>(o.wait_readers),
                 o.wait_timeout_s);
  }
  return Status::Ok();
}

// When each record is due (seconds, recording time) and how loops renumber the records.
class Pacing {
 public:
  explicit Pacing(const fusion::clients::RecordingReader& reader) : reader_(reader) {
    for (std::size_t i = 0; i < reader.size(); ++i) {
      have_receive_times_ = have_receive_times_ && reader.entry(i).receive_time_unix_ns() != 0;
      max_sequence_ = std::max(max_sequence_, reader.entry(i).sequence_number());
    }
  }
  // Paced by the receive times when the recording has them, else by the stamps.
  double RecordTimeS(std::size_t i) const {
    const auto& e = reader_.entry(i);
    return have_receive_times_ ? 1e-9 * static_cast<double>(e.receive_time_unix_ns())
                               : fusion::clients::SecondsFromTime(e.stamp());
  }
  // Sequence numbers keep increasing from loop to loop.
  std::uint64_t SequenceOffset(std::uint64_t loop_index) const {
    return loop_index * (max_sequence_ + 1);
  }

 private:
  const fusion::clients::RecordingReader& reader_;
  bool have_receive_times_ = true;
  std::uint64_t max_sequence_ = 0;
};

// Progress on stderr: a bar on a terminal (every 100 ms), a line every 5 s otherwise.
class Progress {
 public:
  Progress(const Options& o, std::size_t total)
      : tty_(isatty(STDERR_FILENO) != 0), quiet_(o.quiet), loop_(o.loop), total_(total) {}
  bool tty() const { return tty_; }
  // After publishing record i of loop loop_index.
  void Published(std::size_t i, std::uint64_t loop_index) {
    const auto now = Clock::now();
    if (!quiet_ &&
        now - last_ >= (tty_ ? std::chrono::milliseconds(100) : std::chrono::milliseconds(5000))) {
      Print(i + 1, loop_index, false);
      last_ = now;
    }
    if (i + 1 == total_ && !quiet_) Print(total_, loop_index, !loop_);
  }

 private:
  void Print(std::size_t done, std::uint64_t loop_index, bool final_line) const {
    const double elapsed_s = std::chrono::duration<double>(Clock::now() - start_).count();
    if (tty_) {
      constexpr int kBarWidth = 30;
      const int filled = static_cast<int>(kBarWidth * done / total_);
      std::string bar(static_cast<std::size_t>(filled), '#');
      bar.resize(kBarWidth, '.');
      std::fprintf(stderr, "\r[%s] %zu/%zu clouds%s  %.1f s%s", bar.c_str(), done, total_,
                   loop_ ? (" loop " + std::to_string(loop_index + 1)).c_str() : "", elapsed_s,
                   final_line ? "\n" : "");
    } else {
      std::fprintf(stderr, "fusion-replay: %zu/%zu clouds%s, %.1f s\n", done, total_,
                   loop_ ? (" (loop " + std::to_string(loop_index + 1) + ")").c_str() : "",
                   elapsed_s);
    }
  }

  const bool tty_, quiet_, loop_;
  const std::size_t total_;
  const Clock::time_point start_ = Clock::now();
  Clock::time_point last_ = start_ - std::chrono::seconds(10);
};

struct ReplayResult {
  std::uint64_t published = 0;
  Status broken;              // a record that could not be read ends the replay
  bool write_failed = false;  // the bus refused a cloud (reported already)
};

// One pass through the recording, paced unless --fast; false when the replay must end.
bool ReplayOnce(const Options& o, const Pacing& pacing, std::uint64_t loop_index,
                fusion::clients::RecordingReader* reader, fusion::clients::PointCloudWriter* writer,
                Progress* progress, ReplayResult* result) {
  const auto loop_start = Clock::now();
  const double t0_s = pacing.RecordTimeS(0);
  fusion::v1::RecordedCloud cloud;
  for (std::size_t i = 0; i < reader->size() && !fusion::clients::StopRequested(); ++i) {
    if (!o.fast) {
      const double offset_s = std::max(0.0, (pacing.RecordTimeS(i) - t0_s) / o.rate);
      const auto due = loop_start + std::chrono::duration_cast<Clock::duration>(
                                        std::chrono::duration<double>(offset_s));
      if (!fusion::clients::SleepUntilOrStop(due)) break;
    }
    if (Status s = reader->Read(i, &cloud); !s.ok()) {
      result->broken = s;
      return false;
    }
    cloud.set_sequence_number(cloud.sequence_number() + pacing.SequenceOffset(loop_index));
    if (o.restamp)
      *cloud.mutable_stamp() = fusion::clients::TimeFromUnixNs(fusion::clients::UnixNowNs());
    if (Status s = writer->Write(cloud); !s.ok()) {
      std::fprintf(stderr, "\nfusion-replay: %s\n", s.message().c_str());
      result->write_failed = true;
      return false;
    }
    ++result->published;
    progress->Published(i, loop_index);
  }
  return o.loop && reader->tail_error().ok();
}

}  // namespace

int main(int argc, char** argv) {
  Options o;
  if (const auto done = ParseFlags(argc, argv, &o)) return *done;
  if (o.list) return List(o.path);

  std::unique_ptr<fusion::clients::RecordingReader> reader;
  if (Status s = fusion::clients::RecordingReader::Open(o.path, &reader); !s.ok()) {
    return fusion::clients::Fail(kTool, s.message());
  }
  if (!reader->indexed()) {
    std::fprintf(stderr, "fusion-replay: %s: %s; read sequentially (%zu records)\n", o.path.c_str(),
                 reader->index_note().c_str(), reader->size());
  }
  const std::size_t total = reader->size();
  if (total == 0) {
    std::fprintf(stderr, "fusion-replay: %s has no records\n", o.path.c_str());
    return reader->tail_error().ok() ? fusion::clients::kExitOk : fusion::clients::kExitFailure;
  }

  fusion::clients::InstallStopHandlers();
  std::unique_ptr<fusion::clients::PointCloudWriter> writer;
  if (Status s = CreateWriter(o, &writer); !s.ok())
    return fusion::clients::Fail(kTool, s.message());
  std::printf("fusion-replay: publishing %zu clouds from %s on %s in domain %llu\n", total,
              o.path.c_str(), o.topic.c_str(), static_cast<unsigned long long>(o.domain));
  std::fflush(stdout);

  const Pacing pacing(*reader);
  Progress progress(o, total);
  ReplayResult result;
  for (std::uint64_t loop_index = 0; !fusion::clients::StopRequested(); ++loop_index) {
    if (!ReplayOnce(o, pacing, loop_index, reader.get(), writer.get(), &progress, &result)) break;
  }
  if (result.write_failed) return fusion::clients::kExitFailure;
  if (o.qos.reliable) {
    if (Status s = writer->WaitForAcks(std::chrono::seconds(30)); !s.ok()) {
      std::fprintf(stderr, "fusion-replay: not every reader acknowledged: %s\n",
                   s.message().c_str());
    }
  }
  if (progress.tty() && !o.quiet && (fusion::clients::StopRequested() || !result.broken.ok())) {
    std::fputc('\n', stderr);
  }
  if (result.broken.ok() && !reader->tail_error().ok()) result.broken = reader->tail_error();
  if (!result.broken.ok()) {
    std::fprintf(stderr, "fusion-replay: %s: %s; stopped after publishing %llu clouds\n",
                 o.path.c_str(), result.broken.message().c_str(),
                 static_cast<unsigned long long>(result.published));
    return fusion::clients::kExitFailure;
  }
  std::printf("fusion-replay: published %llu clouds\n",
              static_cast<unsigned long long>(result.published));
  return fusion::clients::kExitOk;
}
