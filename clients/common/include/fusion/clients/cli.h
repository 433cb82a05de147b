// Small command-line helpers shared by the client tools: strict number and pose parsing.
#pragma once

#include <cstdint>
#include <string>

#include "fusion/clients/status.h"
#include "fusion/v1/recording.pb.h"

namespace fusion::clients {

// Whole-string conversions; errors name the flag ("--rate: 'abc' is not a number").
Status ParseDouble(const std::string& flag, const std::string& text, double* value);
Status ParseUint(const std::string& flag, const std::string& text, std::uint64_t* value);
// "tx,ty,tz,qx,qy,qz,qw" (metres, Hamilton quaternion, normalised here; must not be zero) or
// "tx,ty,tz" (identity rotation).
Status ParsePose(const std::string& flag, const std::string& text, fusion::v1::RecordedPose* pose);

// Seconds (possibly fractional, since the Unix epoch) to a stamp.
fusion::v1::RecordedTime TimeFromSeconds(double seconds);
double SecondsFromTime(const fusion::v1::RecordedTime& time);
// "1311877813.991479" to a stamp without going through a double (exact to the nanosecond).
Status ParseStamp(const std::string& what, const std::string& text, fusion::v1::RecordedTime* time);

}  // namespace fusion::clients
