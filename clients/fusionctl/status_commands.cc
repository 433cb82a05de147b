// fusionctl health, stats, sensors, reset and save: the service and its map as a whole.
#include <cstdio>

#include "fusionctl.h"
#include "grpc/health/v1/health.grpc.pb.h"

namespace fusionctl {

int Health(Context& ctx, const Args&) {
  auto stub = grpc::health::v1::Health::NewStub(ctx.channel);
  grpc::ClientContext context;
  SetDeadline(&context, ctx.timeout_s);
  grpc::health::v1::HealthCheckResponse reply;
  const auto status = stub->Check(&context, grpc::health::v1::HealthCheckRequest(), &reply);
  if (!status.ok()) return Failed(ctx, status);
  const bool serving = reply.status() == grpc::health::v1::HealthCheckResponse::SERVING;
  std::printf("%s\n", serving ? "SERVING" : "NOT_SERVING");
  return serving ? fusion::clients::kExitOk : fusion::clients::kExitFailure;
}

int Stats(Context& ctx, const Args&) {
  fusion::v1::Stats s;
  const auto status = Call(ctx, &Stub::GetStats, fusion::v1::GetStatsRequest(), &s, ctx.timeout_s);
  if (!status.ok()) return Failed(ctx, status);
  std::printf("map_version        %llu\n", (unsigned long long)s.map_version());
  std::printf("resolution_m       %.3f\n", s.resolution_m());
  std::printf("map_leaves         %llu\n", (unsigned long long)s.map_leaves());
  std::printf("map_memory_bytes   %llu\n", (unsigned long long)s.map_memory_bytes());
  std::printf("sensor_memory      %llu\n", (unsigned long long)s.sensor_memory_bytes());
  std::printf("clouds_received    %llu\n", (unsigned long long)s.clouds_received());
  std::printf("clouds_integrated  %llu\n", (unsigned long long)s.clouds_integrated());
  std::printf("clouds_dropped     %llu\n", (unsigned long long)s.clouds_dropped());
  std::printf("clouds_rejected    %llu\n", (unsigned long long)s.clouds_rejected());
  for (const auto& [reason, count] : s.rejected_by_reason()) {
    std::printf("  rejected %-16s %llu\n", reason.c_str(), (unsigned long long)count);
  }
  std::printf("renders            %llu\n", (unsigned long long)s.renders());
  std::printf("snapshots_saved    %llu\n", (unsigned long long)s.snapshots_saved());
  std::printf("snapshots_failed   %llu\n", (unsigned long long)s.snapshots_failed());
  if (!s.last_snapshot_error().empty()) {
    std::printf("snapshot_error     %s\n", s.last_snapshot_error().c_str());
  }
  if (!s.last_snapshot_path().empty()) {
    std::printf("last_snapshot      %s\n", s.last_snapshot_path().c_str());
  }
  std::printf("uptime_s           %.1f\n", s.uptime_s());
  return fusion::clients::kExitOk;
}

int Sensors(Context& ctx, const Args&) {
  fusion::v1::ListSensorsResponse reply;
  const auto status =
      Call(ctx, &Stub::ListSensors, fusion::v1::ListSensorsRequest(), &reply, ctx.timeout_s);
  if (!status.ok()) return Failed(ctx, status);
  std::printf("%-12s %-8s %9s %13s %10s %10s %9s %9s %9s %10s\n", "sensor", "preset", "beams",
              "memory_bytes", "received", "integrated", "merged", "dropped", "rejected",
              "last_seq");
  for (const auto& s : reply.sensors()) {
    const auto& c = s.counters();
    std::printf("%-12s %-8s %9u %13llu %10llu %10llu %9llu %9llu %9llu %10llu\n", s.id().c_str(),
                s.preset().empty() ? "-" : s.preset().c_str(), s.beams(),
                (unsigned long long)s.memory_bytes(), (unsigned long long)c.received(),
                (unsigned long long)c.integrated(), (unsigned long long)c.merged(),
                (unsigned long long)c.dropped(), (unsigned long long)c.rejected(),
                (unsigned long long)c.last_sequence_number());
    for (const auto& [reason, count] : c.rejected_by_reason()) {
      std::printf("  rejected %-16s %llu\n", reason.c_str(), (unsigned long long)count);
    }
  }
  return fusion::clients::kExitOk;
}

int Reset(Context& ctx, const Args&) {
  fusion::v1::ResetMapResponse reply;
  const auto status =
      Call(ctx, &Stub::ResetMap, fusion::v1::ResetMapRequest(), &reply, ctx.timeout_s);
  if (!status.ok()) return Failed(ctx, status);
  std::printf("map reset, version %llu\n", (unsigned long long)reply.map_version());
  return fusion::clients::kExitOk;
}

int Save(Context& ctx, const Args&) {
  fusion::v1::SaveMapResponse reply;
  const auto status =
      Call(ctx, &Stub::SaveMap, fusion::v1::SaveMapRequest(), &reply, ctx.timeout_s);
  if (!status.ok()) return Failed(ctx, status);
  std::printf("saved %s: %llu bytes, map version %llu\n", reply.path().c_str(),
              (unsigned long long)reply.bytes(), (unsigned long long)reply.map_version());
  return fusion::clients::kExitOk;
}

}  // namespace fusionctl
