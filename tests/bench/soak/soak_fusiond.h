// soak: the fusiond under test as a child process (its stderr log in a file), and its RSS.
#pragma once

#include <signal.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <iterator>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include "../../support/subprocess.h"

namespace fusion::soak {

// A "Vm..." line of /proc/<pid>/status in MB; -1 if the process or the line is gone.
inline double ProcStatusMb(long pid, const std::string& field) {
  std::ifstream in("/proc/" + std::to_string(pid) + "/status");
  for (std::string line; std::getline(in, line);) {
    if (line.rfind(field + ":", 0) == 0) return std::atof(line.c_str() + field.size() + 1) / 1024;
  }
  return -1;
}

// User plus system CPU time of a process (/proc/<pid>/stat), in seconds; -1 if gone.
inline double ProcCpuS(long pid) {
  std::ifstream in("/proc/" + std::to_string(pid) + "/stat");
  std::string stat((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const auto name_end = stat.rfind(')');  // the name may hold spaces
  if (name_end == std::string::npos) return -1;
  std::istringstream fields(stat.substr(name_end + 2));
  std::string field;
  double utime = 0, stime = 0;
  for (int i = 3; i <= 15 && fields >> field; ++i) {  // state is field 3
    if (i == 14) utime = std::atof(field.c_str());
    if (i == 15) stime = std::atof(field.c_str());
  }
  return (utime + stime) / static_cast<double>(sysconf(_SC_CLK_TCK));
}

// The first three fields of /proc/loadavg: the machine's load over 1, 5 and 15 minutes.
inline std::string LoadAverage() {
  std::ifstream in("/proc/loadavg");
  std::string a, b, c;
  in >> a >> b >> c;
  return a + " " + b + " " + c;
}

// This process's CPU time (all threads), in seconds.
inline double OwnCpuS() {
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  return static_cast<double>(usage.ru_utime.tv_sec + usage.ru_stime.tv_sec) +
         static_cast<double>(usage.ru_utime.tv_usec + usage.ru_stime.tv_usec) / 1e6;
}

class FusiondChild {
 public:
  // fusiond `flags`; its stderr goes to log_path (a shell redirects it, then execs fusiond,
  // so the child's pid is fusiond's).
  FusiondChild(const std::string& binary, const std::vector<std::string>& flags,
               const std::string& log_path)
      : command_(binary) {
    std::vector<std::string> argv = {"/bin/sh", "-c", "exec \"$0\" \"$@\" 2>\"$SOAK_FUSIOND_LOG\"",
                                     binary};
    argv.insert(argv.end(), flags.begin(), flags.end());
    for (const auto& flag : flags) command_ += " " + flag;
    process_ = std::make_unique<testing::Subprocess>(
        argv, std::vector<std::string>{"SOAK_FUSIOND_LOG=" + log_path});
  }

  // Waits for "fusiond listening on 127.0.0.1:PORT"; false if it did not come within 20 s.
  bool WaitServing() {
    if (!process_->started()) return false;
    const auto port = process_->WaitForOutput(R"(fusiond listening on 127\.0\.0\.1:(\d+))",
                                              std::chrono::seconds(20));
    if (port) address_ = "127.0.0.1:" + *port;
    return port.has_value();
  }
  [[nodiscard]] const std::string& address() const { return address_; }
  [[nodiscard]] const std::string& command() const { return command_; }
  [[nodiscard]] long pid() const { return process_->pid(); }
  // True while the process runs (it has not exited, been reaped or turned zombie).
  [[nodiscard]] bool Running() const {
    std::ifstream in("/proc/" + std::to_string(pid()) + "/stat");
    std::string pid_text, name, state;
    return static_cast<bool>(in >> pid_text >> name >> state) && state != "Z";
  }
  // SIGTERM, then up to 15 s for the exit; the exit code (128 + signal; -1: no exit).
  int Stop() { return process_->Stop(SIGTERM, std::chrono::seconds(15)); }

 private:
  std::string command_;
  std::unique_ptr<testing::Subprocess> process_;
  std::string address_;
};

// Lines of a log file at warn level or above: their count and the first few.
struct LogSummary {
  std::size_t warnings = 0, errors = 0;
  std::vector<std::string> first_lines;
};

inline LogSummary SummarizeLog(const std::string& path) {
  LogSummary summary;
  std::ifstream in(path);
  for (std::string line; std::getline(in, line);) {
    const bool warning = line.find("[warn") != std::string::npos;
    const bool error =
        line.find("[error") != std::string::npos || line.find("[critical") != std::string::npos;
    summary.warnings += warning ? 1 : 0;
    summary.errors += error ? 1 : 0;
    if ((warning || error) && summary.first_lines.size() < 8) summary.first_lines.push_back(line);
  }
  return summary;
}

}  // namespace fusion::soak
