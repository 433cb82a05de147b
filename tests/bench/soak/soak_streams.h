// soak: StreamUpdates subscribers that connect, stay a random time and leave, over and over.
// Each session is one StreamUpdates call ended by its own deadline (the stay); it is
// recorded with the time to its first message as latency. Sessions start from version 0 (the
// whole map), resume from the last complete version this subscriber saw (the change log), or
// ask for versions only.
#pragma once

#include <grpcpp/grpcpp.h>

#include <atomic>
#include <chrono>
#include <cstdint>
#include <memory>
#include <mutex>
#include <random>
#include <string>

#include "fusion/v1/map_service.grpc.pb.h"
#include "soak_clients.h"
#include "soak_recorder.h"

namespace fusion::soak {

struct StreamTotals {
  std::atomic<std::uint64_t> sessions{0}, messages{0}, voxels{0}, full_messages{0},
      silent_sessions{0};  // ended without a message although they stayed >= 2 s
};

class UpdateSubscriber {
 public:
  UpdateSubscriber(const std::string& address, double stay_min_s, double stay_max_s,
                   Recorder* recorder, StreamTotals* totals, std::uint64_t seed)
      : stub_(v1::FusionMap::NewStub(NewChannel(address))),
        stay_min_s_(stay_min_s),
        stay_max_s_(stay_max_s),
        recorder_(recorder),
        totals_(totals),
        rng_(seed) {}

  void Run(const std::atomic<bool>& stop) {
    while (!stop) Session(stop);
  }
  // Ends the session under way (from another thread) so that Run returns at once.
  void Cancel() {
    std::lock_guard<std::mutex> lock(mutex_);
    if (context_ != nullptr) context_->TryCancel();
  }

 private:
  // What a session checks as messages come: versions never go back, and an incremental batch
  // starts where the previous complete one ended.
  struct SessionState {
    std::uint64_t last_complete = 0;
    bool in_batch = false;
    std::string bad;
  };

  void Check(const v1::MapUpdate& m, SessionState* s) {
    if (!s->in_batch && !m.full() && m.from_version() != s->last_complete && s->bad.empty())
      s->bad = "batch from version " + std::to_string(m.from_version()) + ", expected " +
               std::to_string(s->last_complete);
    if (m.map_version() < s->last_complete && s->bad.empty())
      s->bad = "map_version " + std::to_string(m.map_version()) + " after " +
               std::to_string(s->last_complete);
    s->in_batch = !m.complete();
    if (m.complete()) s->last_complete = m.map_version();
  }

  v1::StreamUpdatesRequest NextRequest() {
    v1::StreamUpdatesRequest request;
    const int mode = static_cast<int>(rng_() % 3);
    if (mode == 1) request.set_since_version(resume_from_);
    if (mode == 2) {
      request.set_since_version(resume_from_);
      request.set_versions_only(true);
    }
    return request;
  }

  void Session(const std::atomic<bool>& stop) {
    const double stay_s = std::uniform_real_distribution<double>(stay_min_s_, stay_max_s_)(rng_);
    const v1::StreamUpdatesRequest request = NextRequest();
    grpc::ClientContext context;
    context.set_deadline(std::chrono::system_clock::now() +
                         std::chrono::microseconds(static_cast<std::int64_t>(stay_s * 1e6)));
    {
      std::lock_guard<std::mutex> lock(mutex_);
      context_ = &context;
    }
    if (stop) context.TryCancel();
    const auto t0 = SoakClock::now();
    double first_ms = -1;
    SessionState state{request.since_version(), false, {}};
    auto reader = stub_->StreamUpdates(&context, request);
    v1::MapUpdate update;
    while (reader->Read(&update)) {
      if (first_ms < 0) first_ms = Ms(SoakClock::now() - t0);
      Count(update);
      Check(update, &state);
    }
    const grpc::Status status = reader->Finish();
    {
      std::lock_guard<std::mutex> lock(mutex_);
      context_ = nullptr;
    }
    if (state.last_complete > resume_from_) resume_from_ = state.last_complete;
    Finish(status, Ms(SoakClock::now() - t0), stay_s, first_ms, state.bad, stop);
  }

  static double Ms(SoakClock::duration d) {
    return std::chrono::duration<double, std::milli>(d).count();
  }

  void Count(const v1::MapUpdate& update) {
    ++totals_->messages;
    totals_->voxels += static_cast<std::uint64_t>(update.voxels_size());
    if (update.full()) ++totals_->full_messages;
  }

  // The session's end: leaving at the deadline (or cancelled at the end of the run) is the
  // normal end; a stream the server ended, or one that failed, is recorded with its code.
  void Finish(const grpc::Status& status, double elapsed_ms, double stay_s, double first_ms,
              const std::string& bad, const std::atomic<bool>& stop) {
    ++totals_->sessions;
    const bool left = (status.error_code() == grpc::StatusCode::DEADLINE_EXCEEDED &&
                       elapsed_ms >= stay_s * 1000 - 100) ||
                      (status.error_code() == grpc::StatusCode::CANCELLED && stop);
    if (!bad.empty()) return recorder_->BadReply(Rpc::kStreamUpdates, bad);
    if (!left) {
      const grpc::Status ended =
          status.ok() ? grpc::Status(grpc::StatusCode::UNKNOWN, "the server ended the stream early")
                      : status;
      return recorder_->Record(Rpc::kStreamUpdates, ended, elapsed_ms);
    }
    if (first_ms < 0 && stay_s >= 2 && !stop) {
      ++totals_->silent_sessions;
      return recorder_->BadReply(Rpc::kStreamUpdates,
                                 "no message in a session of " + std::to_string(stay_s) + " s");
    }
    if (first_ms >= 0) recorder_->Record(Rpc::kStreamUpdates, 0, first_ms);
  }

  std::unique_ptr<v1::FusionMap::Stub> stub_;
  double stay_min_s_, stay_max_s_;
  Recorder* recorder_;
  StreamTotals* totals_;
  std::mt19937_64 rng_;
  std::uint64_t resume_from_ = 0;
  std::mutex mutex_;
  grpc::ClientContext* context_ = nullptr;
};

}  // namespace fusion::soak
