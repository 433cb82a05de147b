// gRPC status codes by name ("INVALID_ARGUMENT"), for the wire's users alike: what fusionctl
// prints and the `code` label of fusiond's RPC metrics.
#pragma once

#include <cstddef>
#include <iterator>

namespace fusion::wire {

// grpc::StatusCode's values are 0..16 in this order (grpc/status.h, fixed by the protocol); a
// code outside them (e.g. from a newer peer) is "UNKNOWN_STATUS".
inline const char* StatusCodeName(int code) {
  static const char* const kNames[] = {"OK",
                                       "CANCELLED",
                                       "UNKNOWN",
                                       "INVALID_ARGUMENT",
                                       "DEADLINE_EXCEEDED",
                                       "NOT_FOUND",
                                       "ALREADY_EXISTS",
                                       "PERMISSION_DENIED",
                                       "RESOURCE_EXHAUSTED",
                                       "FAILED_PRECONDITION",
                                       "ABORTED",
                                       "OUT_OF_RANGE",
                                       "UNIMPLEMENTED",
                                       "INTERNAL",
                                       "UNAVAILABLE",
                                       "DATA_LOSS",
                                       "UNAUTHENTICATED"};
  const auto index = static_cast<std::size_t>(code);
  return code >= 0 && index < std::size(kNames) ? kNames[index] : "UNKNOWN_STATUS";
}

}  // namespace fusion::wire
