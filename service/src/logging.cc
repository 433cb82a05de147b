#include "fusion/service/logging.h"

#include <spdlog/pattern_formatter.h>
#include <spdlog/sinks/ansicolor_sink.h>
#include <spdlog/spdlog.h>
#include <unistd.h>

#include <cstdio>
#include <ctime>
#include <iostream>
#include <mutex>
#include <streambuf>
#include <thread>

namespace fusion::service {
namespace {

void AppendJsonString(const std::string& text, std::string* out) {
  out->push_back('"');
  for (const char c : text) {
    switch (c) {
      case '"': *out += "\\\""; break;
      case '\\': *out += "\\\\"; break;
      case '\n': *out += "\\n"; break;
      case '\r': *out += "\\r"; break;
      case '\t': *out += "\\t"; break;
      default:
        if (static_cast<unsigned char>(c) < 0x20) {
          char escaped[8];
          std::snprintf(escaped, sizeof escaped, "\\u%04x", c);
          *out += escaped;
        } else {
          out->push_back(c);  // UTF-8 passes through; LoggableText already cut it to size
        }
    }
  }
  out->push_back('"');
}

class JsonFormatter final : public spdlog::formatter {
 public:
  void format(const spdlog::details::log_msg& msg, spdlog::memory_buf_t& dest) override {
    const auto since_epoch = msg.time.time_since_epoch();
    const std::time_t seconds = std::chrono::duration_cast<std::chrono::seconds>(since_epoch).count();
    const auto micros =
        std::chrono::duration_cast<std::chrono::microseconds>(since_epoch).count() % 1000000;
    std::tm utc{};
    gmtime_r(&seconds, &utc);
    char time[40];
    const std::size_t n = std::strftime(time, sizeof time, "%Y-%m-%dT%H:%M:%S", &utc);
    std::snprintf(time + n, sizeof time - n, ".%06ldZ", static_cast<long>(micros));
    const auto level = spdlog::level::to_string_view(msg.level);
    const std::string line =
        JsonLogLine(time, std::string(level.data(), level.size()),
                    std::string(msg.logger_name.data(), msg.logger_name.size()),
                    std::string(msg.payload.data(), msg.payload.size()), ::getpid(),
                    static_cast<unsigned long>(msg.thread_id)) +
        "\n";
    dest.append(line.data(), line.data() + line.size());
  }
  [[nodiscard]] std::unique_ptr<spdlog::formatter> clone() const override {
    return std::make_unique<JsonFormatter>();
  }
};

// A foreign line's level: OctoMap marks its warnings and errors, the rest is progress chatter.
spdlog::level::level_enum LevelOfForeignLine(const std::string& line) {
  if (line.rfind("WARNING", 0) == 0 || line.rfind("Warning", 0) == 0) return spdlog::level::warn;
  if (line.rfind("ERROR", 0) == 0 || line.rfind("Error", 0) == 0) return spdlog::level::err;
  return spdlog::level::debug;
}

// A stream buffer that hands every complete line to a logger (OctoMap's std::cout /
// std::cerr). Several threads may write (the persister, the main thread): one lock.
class LineToLog final : public std::streambuf {
 public:
  // Lines go to the logger registered as `logger_name` when they are complete (none yet:
  // dropped), so the logger may be made, or made again, after the capture starts.
  explicit LineToLog(std::string logger_name) : logger_name_(std::move(logger_name)) {}
  // Appends bytes; every complete line is logged (the fd-2 reader uses it too).
  void Write(const char* s, std::size_t n) {
    std::lock_guard<std::mutex> lock(mutex_);
    for (std::size_t i = 0; i < n; ++i) Put(s[i]);
  }
  ~LineToLog() override { Flush(); }

 protected:
  int_type overflow(int_type c) override {
    if (c == traits_type::eof()) return traits_type::not_eof(c);
    std::lock_guard<std::mutex> lock(mutex_);
    Put(static_cast<char>(c));
    return c;
  }
  std::streamsize xsputn(const char* s, std::streamsize n) override {
    std::lock_guard<std::mutex> lock(mutex_);
    for (std::streamsize i = 0; i < n; ++i) Put(s[i]);
    return n;
  }
  int sync() override {
    std::lock_guard<std::mutex> lock(mutex_);
    return 0;  // partial lines wait for their newline ("Reading ... done." comes in pieces)
  }

 private:
  void Put(char c) {
    if (c != '\n') {
      if (line_.size() < 4096) line_.push_back(c);
      return;
    }
    Emit();
  }
  void Emit() {
    // OctoMap ends some lines with spaces or prints a lone " done.": trim, skip empty ones.
    const auto first = line_.find_first_not_of(" \t\r");
    if (first != std::string::npos) {
      const auto last = line_.find_last_not_of(" \t\r");
      const std::string text = line_.substr(first, last - first + 1);
      if (const auto logger = spdlog::get(logger_name_)) {
        logger->log(LevelOfForeignLine(text), "{}", text);
      }
    }
    line_.clear();
  }
  void Flush() {
    std::lock_guard<std::mutex> lock(mutex_);
    if (!line_.empty()) Emit();
  }

  std::string logger_name_;
  std::mutex mutex_;
  std::string line_;
};

#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
constexpr bool kSanitized = true;
#elif defined(__has_feature)
#if __has_feature(address_sanitizer) || __has_feature(thread_sanitizer)
constexpr bool kSanitized = true;
#else
constexpr bool kSanitized = false;
#endif
#else
constexpr bool kSanitized = false;
#endif

// What C code writes to fd 2 (OctoMap's fprintf(stderr, ...), gRPC's own log lines): fd 2
// becomes a pipe that a thread reads into `lines`. Returns the original stderr, where the log
// itself goes. Not in sanitizer builds: a sanitizer's report, written just before the process
// dies, must reach the real stderr.
FILE* CaptureFd2(LineToLog* lines) {
  int fds[2];
  const int original = ::dup(STDERR_FILENO);
  if (kSanitized || original < 0 || ::pipe(fds) != 0) return stderr;
  FILE* log_file = ::fdopen(original, "w");
  if (log_file == nullptr || ::dup2(fds[1], STDERR_FILENO) < 0) return stderr;
  ::close(fds[1]);
  std::thread([fd = fds[0], lines] {
    char buffer[4096];
    for (;;) {
      const ssize_t n = ::read(fd, buffer, sizeof buffer);
      if (n > 0) lines->Write(buffer, static_cast<std::size_t>(n));
      if (n == 0 || (n < 0 && errno != EINTR)) return;
    }
  }).detach();
  return log_file;
}

}  // namespace

bool CapturesFd2() { return !kSanitized; }

std::string JsonLogLine(const std::string& time_utc, const std::string& level,
                        const std::string& logger, const std::string& message, long pid,
                        unsigned long thread) {
  std::string out = "{\"time\":";
  AppendJsonString(time_utc, &out);
  out += ",\"level\":";
  AppendJsonString(level, &out);
  out += ",\"logger\":";
  AppendJsonString(logger, &out);
  out += ",\"message\":";
  AppendJsonString(message, &out);
  out += ",\"pid\":" + std::to_string(pid) + ",\"thread\":" + std::to_string(thread) + "}";
  return out;
}

void SetUpLogging(const std::string& format, const std::string& level) {
  static FILE* log_file = nullptr;
  if (log_file == nullptr) {  // once: foreign output into the "octomap" logger
    // Never freed: std::cout, std::cerr and the fd-2 reader use them until the process exits.
    auto* out = new LineToLog("octomap");
    auto* err = new LineToLog("octomap");
    std::cout.rdbuf(out);
    std::cerr.rdbuf(err);
    log_file = CaptureFd2(err);  // the log itself goes to the original stderr
  }
  auto sink = std::make_shared<spdlog::sinks::ansicolor_sink<spdlog::details::console_mutex>>(
      log_file, format == "json" ? spdlog::color_mode::never : spdlog::color_mode::automatic);
  if (format == "json") sink->set_formatter(std::make_unique<JsonFormatter>());
  spdlog::set_default_logger(std::make_shared<spdlog::logger>("fusiond", sink));
  spdlog::drop("octomap");
  spdlog::register_logger(std::make_shared<spdlog::logger>("octomap", sink));
  spdlog::set_level(spdlog::level::from_str(level));
}

}  // namespace fusion::service
