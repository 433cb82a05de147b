#include "fusion/service/rejection_log.h"

#include <spdlog/spdlog.h>

#include "fusion/service/validation.h"

namespace fusion::service {

void RejectionLog::Log(RejectReason reason, const std::string& sensor_id,
                       const std::string& detail) {
  const auto i = static_cast<std::size_t>(reason);
  const auto now = std::chrono::steady_clock::now();
  std::lock_guard<std::mutex> lock(mutex_);
  if (now - last_[i] < interval_) {
    ++suppressed_[i];
    return;
  }
  last_[i] = now;
  spdlog::warn("ingest: rejected cloud from '{}' ({}): {}{}", LoggableText(sensor_id),
               RejectReasonName(reason), detail,
               suppressed_[i] > 0 ? fmt::format(" [{} more not logged]", suppressed_[i]) : "");
  suppressed_[i] = 0;
}

}  // namespace fusion::service
