#include "handler_support.h"

namespace fusion::service {

using grpc::Status;
using grpc::StatusCode;

bool Expired(const grpc::CallbackServerContext* context) {
  return context->IsCancelled() || context->deadline() < std::chrono::system_clock::now();
}

bool Stopped(const grpc::CallbackServerContext* context, const ServiceState* state) {
  return state->shutting_down || Expired(context);
}

Status AdmitHeavy(ServiceState* state, const char* name, std::optional<CountedSlot>* slot) {
  const auto& limits = state->config.limits();
  // While ingest drops clouds, one expensive call at a time: the rest are shed.
  const bool behind = state->pressure.Behind(*state->queues, std::chrono::steady_clock::now());
  *slot = CountedSlot::Take(&state->heavy_queries, behind ? 1u : limits.max_heavy_queries());
  if (*slot) return Status::OK;
  if (behind) {
    return Status(StatusCode::UNAVAILABLE,
                  std::string(name) + ": fusiond is dropping clouds; one expensive query at a "
                                      "time until ingest keeps up (retry in a second)");
  }
  return Status(StatusCode::RESOURCE_EXHAUSTED,
                std::string(name) + ": " + std::to_string(limits.max_heavy_queries()) +
                    " expensive queries are running already (limits.max_heavy_queries)");
}

Status DeadlineExceeded(const char* what) {
  return Status(StatusCode::DEADLINE_EXCEEDED, std::string(what) + ": deadline passed");
}

}  // namespace fusion::service
