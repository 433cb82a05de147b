// Test helper: runs a program as a child process with its stdout on a pipe.
#pragma once

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <sys/file.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <optional>
#include <regex>
#include <string>
#include <vector>

namespace fusion::testing {

class Subprocess {
 public:
  // Starts argv[0] with the given arguments; extra_env entries are "NAME=value".
  explicit Subprocess(std::vector<std::string> argv, std::vector<std::string> extra_env = {}) {
    int out[2];
    if (pipe(out) != 0) return;
    const pid_t parent = getpid();
    pid_ = fork();
    if (pid_ == 0) {
      // A test that dies (a sanitizer abort, a crash) takes its processes with it: an orphaned
      // fusiond would keep ctest waiting on the output pipe until its timeout. (The signal comes
      // when the thread that forked ends: start processes from threads that outlive them.)
      prctl(PR_SET_PDEATHSIG, SIGKILL);
      if (getppid() != parent) _exit(127);  // the parent died before prctl
      dup2(out[1], STDOUT_FILENO);
      close(out[0]);
      close(out[1]);
      for (auto& e : extra_env) putenv(e.data());
      std::vector<char*> args;
      for (auto& a : argv) args.push_back(a.data());
      args.push_back(nullptr);
      execv(args[0], args.data());
      _exit(127);
    }
    close(out[1]);
    stdout_fd_ = out[0];
    fcntl(stdout_fd_, F_SETFL, O_NONBLOCK);
  }
  ~Subprocess() {
    if (pid_ > 0 && !exit_status_) {
      kill(pid_, SIGKILL);
      waitpid(pid_, nullptr, 0);
    }
    if (stdout_fd_ >= 0) close(stdout_fd_);
  }
  Subprocess(const Subprocess&) = delete;
  Subprocess& operator=(const Subprocess&) = delete;

  [[nodiscard]] bool started() const { return pid_ > 0; }
  [[nodiscard]] pid_t pid() const { return pid_; }

  // Reads stdout until `pattern` matches the text so far or the timeout passes; returns the
  // first capture group (or the whole match).
  std::optional<std::string> WaitForOutput(const std::string& pattern,
                                           std::chrono::milliseconds timeout) {
    const std::regex re(pattern);
    const auto end = std::chrono::steady_clock::now() + timeout;
    while (std::chrono::steady_clock::now() < end) {
      std::smatch match;
      if (std::regex_search(output_, match, re)) return match.size() > 1 ? match[1] : match[0];
      pollfd pfd{stdout_fd_, POLLIN, 0};
      poll(&pfd, 1, 50);
      char buffer[4096];
      const ssize_t n = read(stdout_fd_, buffer, sizeof buffer);
      if (n > 0) output_.append(buffer, static_cast<size_t>(n));
      if (n == 0) break;  // closed: the child has exited
    }
    std::smatch match;
    if (std::regex_search(output_, match, re)) return match.size() > 1 ? match[1] : match[0];
    return std::nullopt;
  }
  [[nodiscard]] const std::string& output() const { return output_; }

  // Sends a signal and waits for the exit; returns the exit code, 128+signal if killed by a
  // signal, or -1 on timeout.
  int Stop(int signal_number, std::chrono::milliseconds timeout) {
    if (pid_ <= 0) return -1;
    kill(pid_, signal_number);
    return Wait(timeout);
  }
  int Wait(std::chrono::milliseconds timeout) {
    const auto end = std::chrono::steady_clock::now() + timeout;
    while (std::chrono::steady_clock::now() < end) {
      int status = 0;
      if (waitpid(pid_, &status, WNOHANG) == pid_) {
        exit_status_ = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
        return *exit_status_;
      }
      usleep(10000);
    }
    return -1;
  }

 private:
  pid_t pid_ = -1;
  int stdout_fd_ = -1;
  std::string output_;
  std::optional<int> exit_status_;
};

// DDS domain ids private to this test process (tests run in parallel): the n-th id this
// process holds, n = 0, 1, ... Each id in 1..200 is claimed with an exclusive lock on
// /tmp/fusion-test-dds-domain-<id>.lock, released when the process exits, so two test
// processes never share a domain (a pid-derived guess alone collides now and then).
inline unsigned PrivateDomainId(unsigned n = 0) {
  static std::vector<unsigned> held;
  static unsigned next = static_cast<unsigned>(getpid());
  for (unsigned tries = 0; held.size() <= n && tries < 200; ++tries) {
    const unsigned id = 1 + next++ % 200;
    const std::string path = "/tmp/fusion-test-dds-domain-" + std::to_string(id) + ".lock";
    const int fd = open(path.c_str(), O_CREAT | O_RDWR | O_CLOEXEC, 0666);
    if (fd < 0) continue;
    if (flock(fd, LOCK_EX | LOCK_NB) == 0) {
      held.push_back(id);  // the descriptor stays open: the lock lasts as long as the process
    } else {
      close(fd);
    }
  }
  // Every id taken (or /tmp not writable): fall back to a guess.
  if (held.size() <= n) return 1 + (static_cast<unsigned>(getpid()) + 41 * n) % 200;
  return held[n];
}

}  // namespace fusion::testing
