// soak: what every call ended with (status code, latency), per RPC, shared by all clients.
#pragma once

#include <grpcpp/grpcpp.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <map>
#include <mutex>
#include <string>
#include <vector>

namespace fusion::soak {

enum class Rpc {
  kGetStats,
  kQueryPoints,
  kQueryBox,
  kCastRay,
  kFindPlanes,
  kGetSnapshot,
  kStreamUpdates,
  kListSensors,
  kInspectBeam,
  kResetMap,
  kSaveMap,
  kCount
};
constexpr std::size_t kRpcCount = static_cast<std::size_t>(Rpc::kCount);

inline const char* RpcName(Rpc rpc) {
  static constexpr std::array<const char*, kRpcCount> kNames = {
      "GetStats",      "QueryPoints", "QueryBox",    "CastRay",  "FindPlanes", "GetSnapshot",
      "StreamUpdates", "ListSensors", "InspectBeam", "ResetMap", "SaveMap"};
  return kNames[static_cast<std::size_t>(rpc)];
}

// grpc::StatusCode's name; "BAD_REPLY" (-1) is the soak's own: an OK answer that is wrong.
constexpr int kBadReply = -1;
inline std::string CodeName(int code) {
  static const std::map<int, const char*> kNames = {
      {kBadReply, "BAD_REPLY"},   {0, "OK"},
      {1, "CANCELLED"},           {2, "UNKNOWN"},
      {3, "INVALID_ARGUMENT"},    {4, "DEADLINE_EXCEEDED"},
      {5, "NOT_FOUND"},           {6, "ALREADY_EXISTS"},
      {7, "PERMISSION_DENIED"},   {8, "RESOURCE_EXHAUSTED"},
      {9, "FAILED_PRECONDITION"}, {10, "ABORTED"},
      {11, "OUT_OF_RANGE"},       {12, "UNIMPLEMENTED"},
      {13, "INTERNAL"},           {14, "UNAVAILABLE"},
      {15, "DATA_LOSS"},          {16, "UNAUTHENTICATED"}};
  const auto it = kNames.find(code);
  return it != kNames.end() ? it->second : "CODE_" + std::to_string(code);
}

// Load shedding, not a failure: the service said it is full or going away.
inline bool IsShed(int code) {
  return code == grpc::StatusCode::RESOURCE_EXHAUSTED || code == grpc::StatusCode::UNAVAILABLE;
}

// Nearest-rank percentile of unsorted values (NAN if none).
inline double Percentile(std::vector<float> v, double q) {
  if (v.empty()) return NAN;
  const auto rank = static_cast<std::size_t>(std::ceil(q * static_cast<double>(v.size())));
  const std::size_t k = std::min(v.size() - 1, rank == 0 ? 0 : rank - 1);
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(k), v.end());
  return v[k];
}

// Per RPC: latency of the OK calls, calls by status code, the first messages of each error.
struct RpcRecord {
  std::vector<float> latency_ms;  // OK calls
  std::map<int, std::uint64_t> calls_by_code;
  std::map<int, std::vector<std::string>> first_messages;  // up to 3 distinct per code

  [[nodiscard]] std::uint64_t Count(bool (*which)(int)) const {
    std::uint64_t n = 0;
    for (const auto& [code, count] : calls_by_code) n += which(code) ? count : 0;
    return n;
  }
};

inline bool AnyCode(int) { return true; }
inline bool OkCode(int code) { return code == 0; }
inline bool ShedCode(int code) { return IsShed(code); }
inline bool ErrorCode(int code) { return code != 0 && !IsShed(code); }

class Recorder {
 public:
  void Record(Rpc rpc, const grpc::Status& status, double latency_ms) {
    Record(rpc, status.error_code(), latency_ms, status.error_message());
  }
  void Record(Rpc rpc, int code, double latency_ms, const std::string& message = {}) {
    std::lock_guard<std::mutex> lock(mutex_);
    RpcRecord& r = records_[static_cast<std::size_t>(rpc)];
    ++r.calls_by_code[code];
    if (code == 0) {
      r.latency_ms.push_back(static_cast<float>(latency_ms));
      return;
    }
    auto& messages = r.first_messages[code];
    if (messages.size() < 3 &&
        std::find(messages.begin(), messages.end(), message) == messages.end())
      messages.push_back(message);
  }
  void BadReply(Rpc rpc, const std::string& what) { Record(rpc, kBadReply, 0, what); }

  // A copy of everything so far.
  [[nodiscard]] std::array<RpcRecord, kRpcCount> Records() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return records_;
  }
  // Calls, shed and errors so far over all RPCs.
  struct Totals {
    std::uint64_t calls = 0, shed = 0, errors = 0;
  };
  [[nodiscard]] Totals Sum() const {
    std::lock_guard<std::mutex> lock(mutex_);
    Totals t;
    for (const auto& r : records_) {
      t.calls += r.Count(AnyCode);
      t.shed += r.Count(ShedCode);
      t.errors += r.Count(ErrorCode);
    }
    return t;
  }

 private:
  mutable std::mutex mutex_;
  std::array<RpcRecord, kRpcCount> records_;
};

}  // namespace fusion::soak
