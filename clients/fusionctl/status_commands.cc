// fusionctl health, stats, sensors, reset, clear-box and save: the service and its map as a
// whole.
#include <cstdio>
#include <map>

#include "fusionctl.h"
#include "grpc/health/v1/health.grpc.pb.h"

namespace fusionctl {
namespace {

using ULL = unsigned long long;

// A proto map in key order: the text output stays stable from call to call.
void PrintByReason(const google::protobuf::Map<std::string, std::uint64_t>& by_reason,
                   const char* indent) {
  const std::map<std::string, std::uint64_t> sorted(by_reason.begin(), by_reason.end());
  for (const auto& [reason, count] : sorted) {
    std::printf("%s%-18s %llu\n", indent, reason.c_str(), (ULL)count);
  }
}

const char* OrDash(const std::string& s) { return s.empty() ? "-" : s.c_str(); }

}  // namespace

int Health(Context& ctx, const Args&) {
  auto stub = grpc::health::v1::Health::NewStub(ctx.channel);
  grpc::ClientContext context;
  PrepareCall(ctx, &context, ctx.timeout_s);
  grpc::health::v1::HealthCheckResponse reply;
  const auto status = stub->Check(&context, grpc::health::v1::HealthCheckRequest(), &reply);
  if (!status.ok()) return Failed(ctx, status);
  const bool serving = reply.status() == grpc::health::v1::HealthCheckResponse::SERVING;
  if (ctx.json) {
    PrintJson(reply);
  } else {
    std::printf("%s\n", serving ? "SERVING" : "NOT_SERVING");
  }
  return serving ? fusion::clients::kExitOk : fusion::clients::kExitFailure;
}

// Every field of fusion.v1.Stats, under its .proto name (the unit test checks the list
// against the message's descriptor).
int Stats(Context& ctx, const Args&) {
  fusion::v1::Stats s;
  const auto status = Call(ctx, &Stub::GetStats, fusion::v1::GetStatsRequest(), &s);
  if (!status.ok()) return Failed(ctx, status);
  if (ctx.json) {
    PrintJson(s);
    return fusion::clients::kExitOk;
  }
  const auto row = [](const char* name, ULL value) { std::printf("%-20s %llu\n", name, value); };
  row("map_version", s.map_version());
  std::printf("%-20s %.3f\n", "resolution_m", s.resolution_m());
  row("map_leaves", s.map_leaves());
  row("map_memory_bytes", s.map_memory_bytes());
  row("sensor_memory_bytes", s.sensor_memory_bytes());
  row("clouds_received", s.clouds_received());
  row("clouds_integrated", s.clouds_integrated());
  row("clouds_in_map", s.clouds_in_map());
  row("clouds_dropped", s.clouds_dropped());
  row("clouds_rejected", s.clouds_rejected());
  std::printf("rejected_by_reason%s\n", s.rejected_by_reason().empty() ? "   -" : "");
  PrintByReason(s.rejected_by_reason(), "  ");
  row("matched_writers", s.matched_writers());
  row("matched_writers_total", s.matched_writers_total());
  row("changes_detected", s.changes_detected());
  row("renders", s.renders());
  row("snapshots_saved", s.snapshots_saved());
  row("snapshots_failed", s.snapshots_failed());
  std::printf("%-20s %s\n", "last_snapshot_path", OrDash(s.last_snapshot_path()));
  std::printf("%-20s %s\n", "last_snapshot_error", OrDash(s.last_snapshot_error()));
  std::printf("%-20s %.1f\n", "uptime_s", s.uptime_s());
  return fusion::clients::kExitOk;
}

int Sensors(Context& ctx, const Args&) {
  fusion::v1::ListSensorsResponse reply;
  const auto status = Call(ctx, &Stub::ListSensors, fusion::v1::ListSensorsRequest(), &reply);
  if (!status.ok()) return Failed(ctx, status);
  if (ctx.json) {
    PrintJson(reply);
    return fusion::clients::kExitOk;
  }
  std::printf("%-12s %-8s %9s %13s %10s %10s %9s %9s %9s %10s\n", "sensor", "preset", "beams",
              "memory_bytes", "received", "integrated", "merged", "dropped", "rejected",
              "last_seq");
  for (const auto& s : reply.sensors()) {
    const auto& c = s.counters();
    std::printf("%-12s %-8s %9u %13llu %10llu %10llu %9llu %9llu %9llu %10llu\n", s.id().c_str(),
                OrDash(s.preset()), s.beams(), (ULL)s.memory_bytes(), (ULL)c.received(),
                (ULL)c.integrated(), (ULL)c.merged(), (ULL)c.dropped(), (ULL)c.rejected(),
                (ULL)c.last_sequence_number());
    PrintByReason(c.rejected_by_reason(), "  rejected ");
  }
  return fusion::clients::kExitOk;
}

int Reset(Context& ctx, const Args&) {
  fusion::v1::ResetMapResponse reply;
  const auto status = Call(ctx, &Stub::ResetMap, fusion::v1::ResetMapRequest(), &reply);
  if (!status.ok()) return Failed(ctx, status);
  if (ctx.json) {
    PrintJson(reply);
  } else {
    std::printf("map reset, version %llu\n", (ULL)reply.map_version());
  }
  return fusion::clients::kExitOk;
}

int ClearBox(Context& ctx, const Args& args) {
  fusion::v1::ClearBoxRequest request;
  if (!ParsePoint(args.positional, 0, request.mutable_min()) ||
      !ParsePoint(args.positional, 3, request.mutable_max())) {
    return Usage("clear-box needs MINX MINY MINZ MAXX MAXY MAXZ");
  }
  fusion::v1::ClearBoxResponse reply;
  const auto status = Call(ctx, &Stub::ClearBox, request, &reply);
  if (!status.ok()) return Failed(ctx, status);
  if (ctx.json) {
    PrintJson(reply);
  } else {
    std::printf("box cleared: %llu voxels forgotten, version %llu\n",
                (ULL)reply.voxels_cleared(), (ULL)reply.map_version());
  }
  return fusion::clients::kExitOk;
}

int Save(Context& ctx, const Args&) {
  fusion::v1::SaveMapResponse reply;
  const auto status = Call(ctx, &Stub::SaveMap, fusion::v1::SaveMapRequest(), &reply);
  if (!status.ok()) return Failed(ctx, status);
  if (ctx.json) {
    PrintJson(reply);
  } else {
    std::printf("saved %s: %llu bytes, map version %llu\n", reply.path().c_str(),
                (ULL)reply.bytes(), (ULL)reply.map_version());
  }
  return fusion::clients::kExitOk;
}

}  // namespace fusionctl
