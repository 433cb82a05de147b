// Command-line helpers shared by every client tool (fusion-import, -record, -replay,
// -sim-sensor, fusionctl): exit codes, usage and error messages, the SIGINT/SIGTERM stop flag,
// strict number, pose and time parsing.
#pragma once

#include <chrono>
#include <cstdint>
#include <string>

#include "fusion/core/status.h"
#include "fusion/v1/recording.pb.h"

namespace fusion::clients {

// Exit codes of the client tools.
inline constexpr int kExitOk = 0;
inline constexpr int kExitFailure = 1;  // the work failed: a file, the bus, the service
inline constexpr int kExitUsage = 2;    // a bad command line

// --help or -h.
bool IsHelpFlag(const std::string& arg);
// Writes `usage` to stdout; returns kExitOk (what --help exits with).
int PrintHelp(const char* usage);
// "<tool>: <message> (see <tool> --help)" on stderr; returns kExitUsage.
int UsageError(const std::string& tool, const std::string& message);
// "<tool>: <message>" on stderr; returns kExitFailure.
int Fail(const std::string& tool, const std::string& message);

// The value of the option at argv[*i]: advances *i to it; false (and *i unchanged) when the
// option is the last argument.
bool TakeValue(int argc, char** argv, int* i, std::string* value);

// SIGINT and SIGTERM set a stop flag (and do nothing else) once these are installed, so the
// tools can finish cleanly: flush, write the index, wait for acknowledgements.
void InstallStopHandlers();
bool StopRequested();
// Sleeps until `due`, waking every 100 ms at the latest to look at the stop flag; returns
// false when a stop was requested (at once, or during the sleep).
bool SleepUntilOrStop(std::chrono::steady_clock::time_point due);

// Whole-string conversions; errors name the flag ("--rate: 'abc' is not a number").
Status ParseDouble(const std::string& flag, const std::string& text, double* value);
Status ParseUint(const std::string& flag, const std::string& text, std::uint64_t* value);
// A DDS domain id, 0..230 (ParseUint, then the range).
Status ParseDomain(const std::string& flag, const std::string& text, std::uint64_t* domain);
// Whole-string finite number without a message (fusionctl's own wording); unlike ParseDouble
// it accepts values that underflow to zero or a denormal. *value is written even on failure.
bool ParseFinite(const std::string& text, double* value);
// "tx,ty,tz,qx,qy,qz,qw" (metres, Hamilton quaternion, normalised here; must not be zero) or
// "tx,ty,tz" (identity rotation).
Status ParsePose(const std::string& flag, const std::string& text, fusion::v1::RecordedPose* pose);

// Seconds (possibly fractional, since the Unix epoch) to a stamp.
fusion::v1::RecordedTime TimeFromSeconds(double seconds);
// Nanoseconds since the Unix epoch (e.g. UnixNowNs()) to a stamp.
fusion::v1::RecordedTime TimeFromUnixNs(std::int64_t unix_ns);
double SecondsFromTime(const fusion::v1::RecordedTime& time);
// "1311877813.991479" to a stamp without going through a double (exact to the nanosecond).
Status ParseStamp(const std::string& what, const std::string& text, fusion::v1::RecordedTime* time);

}  // namespace fusion::clients
