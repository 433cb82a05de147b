// Rate-limited log lines of rejected samples: at most one line per reason per interval, the
// ones held back counted into the next line of that reason. Shared by the ingest threads and
// DDS's threads (the topic filter), so it locks.
#pragma once

#include <array>
#include <chrono>
#include <cstdint>
#include <mutex>
#include <string>

#include "fusion/service/cloud.h"

namespace fusion::service {

class RejectionLog {
 public:
  explicit RejectionLog(std::chrono::milliseconds interval) : interval_(interval) {}

  // "ingest: rejected cloud from '<id>' (<reason>): <detail>", at warn; the id is escaped.
  void Log(RejectReason reason, const std::string& sensor_id, const std::string& detail);

 private:
  std::chrono::milliseconds interval_;
  std::mutex mutex_;
  std::array<std::chrono::steady_clock::time_point, kRejectReasonCount> last_{};
  std::array<std::uint64_t, kRejectReasonCount> suppressed_{};
};

}  // namespace fusion::service
