// fusiond's log: spdlog to stderr, as text for people or one JSON object a line for log
// collectors (`log_format`), and OctoMap's console output (it writes progress and warnings to
// std::cout / std::cerr) routed through the same logger, so no foreign line reaches the log
// and stdout carries only the "listening on" line.
#pragma once

#include <string>

namespace fusion::service {

// Sets up the default logger ("fusiond") at `level` in `format` ("text" or "json") and
// captures std::cout / std::cerr into the logger "octomap" (their lines at debug / warn).
void SetUpLogging(const std::string& format, const std::string& level);

// Whether what C code writes to fd 2 (OctoMap's fprintf(stderr, ...), gRPC's log lines) is
// captured too. Not in sanitizer builds: a sanitizer's report must reach the real stderr.
[[nodiscard]] bool CapturesFd2();

// One JSON object of a log line: {"time", "level", "logger", "message", "pid", "thread"};
// the message escaped as JSON requires. For tests and the formatter.
[[nodiscard]] std::string JsonLogLine(const std::string& time_utc, const std::string& level,
                                      const std::string& logger, const std::string& message,
                                      long pid, unsigned long thread);

}  // namespace fusion::service
