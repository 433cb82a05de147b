#include "fusion/clients/cli.h"

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <sstream>
#include <thread>
#include <vector>

namespace fusion::clients {

namespace {

// Lock-free, so setting it is async-signal-safe.
std::atomic<bool> g_stop_requested{false};
static_assert(std::atomic<bool>::is_always_lock_free);

void OnStopSignal(int) { g_stop_requested = true; }

}  // namespace

bool IsHelpFlag(const std::string& arg) { return arg == "--help" || arg == "-h"; }

int PrintHelp(const char* usage) {
  std::fputs(usage, stdout);
  return kExitOk;
}

int UsageError(const std::string& tool, const std::string& message) {
  std::fprintf(stderr, "%s: %s (see %s --help)\n", tool.c_str(), message.c_str(), tool.c_str());
  return kExitUsage;
}

int Fail(const std::string& tool, const std::string& message) {
  std::fprintf(stderr, "%s: %s\n", tool.c_str(), message.c_str());
  return kExitFailure;
}

bool TakeValue(int argc, char** argv, int* i, std::string* value) {
  if (*i + 1 >= argc) return false;
  *value = argv[++*i];
  return true;
}

void InstallStopHandlers() {
  std::signal(SIGINT, OnStopSignal);
  std::signal(SIGTERM, OnStopSignal);
}

bool StopRequested() { return g_stop_requested; }

bool SleepUntilOrStop(std::chrono::steady_clock::time_point due) {
  using Clock = std::chrono::steady_clock;
  while (!StopRequested() && Clock::now() < due) {
    std::this_thread::sleep_until(std::min(due, Clock::now() + std::chrono::milliseconds(100)));
  }
  return !StopRequested();
}

bool ParseFinite(const std::string& text, double* value) {
  char* end = nullptr;
  *value = std::strtod(text.c_str(), &end);
  return !text.empty() && *end == '\0' && std::isfinite(*value);
}

Status ParseDouble(const std::string& flag, const std::string& text, double* value) {
  char* end = nullptr;
  errno = 0;
  const double v = std::strtod(text.c_str(), &end);
  if (text.empty() || end != text.c_str() + text.size() || errno != 0 || !std::isfinite(v)) {
    return Status::Error(flag + ": '" + text + "' is not a finite number");
  }
  *value = v;
  return Status::Ok();
}

Status ParseUint(const std::string& flag, const std::string& text, std::uint64_t* value) {
  char* end = nullptr;
  errno = 0;
  const unsigned long long v = std::strtoull(text.c_str(), &end, 10);
  if (text.empty() || text[0] == '-' || end != text.c_str() + text.size() || errno != 0) {
    return Status::Error(flag + ": '" + text + "' is not a non-negative integer");
  }
  *value = v;
  return Status::Ok();
}

Status ParseDomain(const std::string& flag, const std::string& text, std::uint64_t* domain) {
  if (Status s = ParseUint(flag, text, domain); !s.ok()) return s;
  if (*domain > 230) return Status::Error(flag + " must be 0..230");
  return Status::Ok();
}

Status ParsePose(const std::string& flag, const std::string& text, fusion::v1::RecordedPose* pose) {
  std::vector<double> values;
  std::stringstream stream(text);
  std::string item;
  while (std::getline(stream, item, ',')) {
    double v = 0;
    if (Status s = ParseDouble(flag, item, &v); !s.ok()) return s;
    values.push_back(v);
  }
  if (values.size() != 3 && values.size() != 7) {
    return Status::Error(flag + ": expected tx,ty,tz or tx,ty,tz,qx,qy,qz,qw, got '" + text + "'");
  }
  pose->set_tx(values[0]);
  pose->set_ty(values[1]);
  pose->set_tz(values[2]);
  double q[4] = {0, 0, 0, 1};
  if (values.size() == 7) {
    const double norm = std::sqrt(values[3] * values[3] + values[4] * values[4] +
                                  values[5] * values[5] + values[6] * values[6]);
    if (norm < 1e-9) return Status::Error(flag + ": the quaternion is zero");
    for (int i = 0; i < 4; ++i) q[i] = values[3 + i] / norm;
  }
  pose->set_qx(q[0]);
  pose->set_qy(q[1]);
  pose->set_qz(q[2]);
  pose->set_qw(q[3]);
  return Status::Ok();
}

fusion::v1::RecordedTime TimeFromSeconds(double seconds) {
  fusion::v1::RecordedTime time;
  double whole = std::floor(seconds);
  auto nanosec = static_cast<std::int64_t>(std::llround((seconds - whole) * 1e9));
  if (nanosec >= 1000000000) {
    whole += 1;
    nanosec -= 1000000000;
  }
  time.set_sec(static_cast<std::int32_t>(whole));
  time.set_nanosec(static_cast<std::uint32_t>(nanosec));
  return time;
}

fusion::v1::RecordedTime TimeFromUnixNs(std::int64_t unix_ns) {
  fusion::v1::RecordedTime time;
  time.set_sec(static_cast<std::int32_t>(unix_ns / 1000000000));
  time.set_nanosec(static_cast<std::uint32_t>(unix_ns % 1000000000));
  return time;
}

Status ParseStamp(const std::string& what, const std::string& text,
                  fusion::v1::RecordedTime* time) {
  const std::size_t dot = text.find('.');
  const std::string whole = text.substr(0, dot);
  std::string fraction = dot == std::string::npos ? "" : text.substr(dot + 1);
  std::uint64_t sec = 0, nanosec = 0;
  const Status bad = Status::Error(what + ": '" + text + "' is not a time in seconds");
  if (!ParseUint(what, whole, &sec).ok() || sec > 0x7fffffffu || fraction.size() > 9) return bad;
  if (!fraction.empty() && !ParseUint(what, fraction, &nanosec).ok()) return bad;
  for (std::size_t i = fraction.size(); i < 9; ++i) nanosec *= 10;
  time->set_sec(static_cast<std::int32_t>(sec));
  time->set_nanosec(static_cast<std::uint32_t>(nanosec));
  return Status::Ok();
}

double SecondsFromTime(const fusion::v1::RecordedTime& time) {
  return static_cast<double>(time.sec()) + 1e-9 * static_cast<double>(time.nanosec());
}

}  // namespace fusion::clients
