// What every MapService handler is made of: a body run so that no exception escapes, on gRPC's
// thread (Unary) or, for the expensive calls, admitted and run on the heavy-query pool (Heavy),
// and the checks long loops poll. Internal to service/src.
#pragma once

#include <grpcpp/grpcpp.h>
#include <spdlog/spdlog.h>

#include <memory>
#include <optional>
#include <string>

#include "fusion/service/map_service.h"

namespace fusion::service {

// The deadline passed or the client cancelled.
[[nodiscard]] bool Expired(const grpc::CallbackServerContext* context);
// Expired, or fusiond shutting down: what an expensive call's loops poll.
[[nodiscard]] bool Stopped(const grpc::CallbackServerContext* context, const ServiceState* state);
[[nodiscard]] grpc::Status DeadlineExceeded(const char* what);
// Admission of an expensive call (docs/service.md, "Overload"): OK with *slot held, or the
// status that sheds it: RESOURCE_EXHAUSTED when limits.max_heavy_queries run already; while
// ingest drops clouds only one runs at a time, the others get UNAVAILABLE.
[[nodiscard]] grpc::Status AdmitHeavy(ServiceState* state, const char* name,
                                      std::optional<CountedSlot>* slot);

// Runs a handler body: no exception escapes, every outcome is a status.
template <typename Body>
grpc::Status RunBody(const ServiceState* state, const char* name, Body& body) {
  grpc::Status status;
  if (state->shutting_down) {
    status = grpc::Status(grpc::StatusCode::UNAVAILABLE, "fusiond is shutting down");
  } else {
    try {
      status = body();
    } catch (const std::bad_alloc&) {
      status =
          grpc::Status(grpc::StatusCode::RESOURCE_EXHAUSTED, std::string(name) + ": out of memory");
    } catch (const std::exception& e) {
      spdlog::error("{}: {}", name, e.what());
      status = grpc::Status(grpc::StatusCode::INTERNAL, std::string(name) + ": " + e.what());
    }
  }
  if (!status.ok()) spdlog::debug("{}: {} {}", name, status.error_code(), status.error_message());
  return status;
}

// A cheap call: answered on gRPC's thread, finished once.
template <typename Body>
grpc::ServerUnaryReactor* Unary(grpc::CallbackServerContext* context, const ServiceState* state,
                                const char* name, Body&& body) {
  auto* reactor = context->DefaultReactor();
  reactor->Finish(RunBody(state, name, body));
  return reactor;
}

// An expensive call: admitted (AdmitHeavy), then run on the low-priority query pool. The body
// must capture by value what it uses (the request and reply live until Finish).
template <typename Body>
grpc::ServerUnaryReactor* Heavy(grpc::CallbackServerContext* context, ServiceState* state,
                                const char* name, Body body) {
  auto* reactor = context->DefaultReactor();
  std::optional<CountedSlot> slot;
  grpc::Status admitted =
      state->shutting_down ? grpc::Status(grpc::StatusCode::UNAVAILABLE, "fusiond is shutting down")
                           : AdmitHeavy(state, name, &slot);
  if (!admitted.ok()) {
    reactor->Finish(admitted);
    return reactor;
  }
  auto held = std::make_shared<std::optional<CountedSlot>>(std::move(slot));
  state->heavy_pool->Post([reactor, state, name, body, held]() mutable {
    grpc::Status status = RunBody(state, name, body);
    held->reset();  // free before the client hears back: its next call finds the slot
    reactor->Finish(status);
  });
  return reactor;
}

}  // namespace fusion::service
