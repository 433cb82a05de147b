// fusionctl: command-line client of fusiond. Speaks only the wire types (proto/).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <functional>
#include <map>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include <unistd.h>

#include <grpcpp/grpcpp.h>
#include <octomap/AbstractOcTree.h>
#include <octomap/OcTree.h>

#include "fusion/v1/map_service.grpc.pb.h"
#include "grpc/health/v1/health.grpc.pb.h"
#include "map_render.h"

namespace {

using fusion::v1::FusionMap;

constexpr const char* kUsage = R"(fusionctl: command-line client of fusiond

Usage: fusionctl [--server HOST:PORT] [--timeout SECONDS] COMMAND [ARGS] [OPTIONS]
  --server HOST:PORT   fusiond's gRPC address (default $FUSIOND_ADDRESS or 127.0.0.1:50051)
  --timeout SECONDS    deadline of each call (default 10, at least 60 for planes and
                       snapshots; watch: none)

Commands:
  health                        grpc.health.v1 check; exit 0 when SERVING
  stats                         map version, counters, memory
  sensors                       configured sensors and their ingest counters
  points X,Y,Z [X,Y,Z ...]      occupancy of points (world frame, metres)
  box MINX MINY MINZ MAXX MAXY MAXZ [--state occupied|free|unknown]... [--limit N]
                                voxels in a box, all pages (at most --limit, default 100000)
  ray OX OY OZ DX DY DZ [--max-range M] [--ignore-unknown]
                                first occupied voxel along a ray
  planes [--max N] [--region MINX MINY MINZ MAXX MAXY MAXZ] [--min-support N]
                                planes found by the Hough transform
  snapshot FILE.bt|FILE.ot      write the map in OctoMap's format (by extension)
  render FILE.png [--color height|probability] [--azimuth DEG] [--elevation DEG]
         [--size WxH] [--min-probability P]
                                a picture of the occupied voxels
  watch [--since VERSION] [--count N] [--versions-only]
                                stream map updates (Ctrl-C to stop); --versions-only:
                                announce new versions without their voxels
  beam SENSOR ROW COL           p(B) and p(m) of one beam, as a table
  reset                         clear the map and every beam grid
  save                          write a snapshot to the service's persistence path
  help                          this text
)";

struct Context {
  std::string server;
  double timeout_s = 10.0;
  std::shared_ptr<grpc::Channel> channel;
  std::unique_ptr<FusionMap::Stub> stub;
};

void SetDeadline(grpc::ClientContext* context, double seconds) {
  context->set_deadline(std::chrono::system_clock::now() +
                        std::chrono::milliseconds(static_cast<long>(seconds * 1000)));
}

int Failed(const Context& ctx, const grpc::Status& status) {
  if (status.error_code() == grpc::StatusCode::UNAVAILABLE ||
      status.error_code() == grpc::StatusCode::DEADLINE_EXCEEDED) {
    std::fprintf(stderr, "fusionctl: cannot reach fusiond at %s: %s\n", ctx.server.c_str(),
                 status.error_message().c_str());
  } else {
    std::fprintf(stderr, "fusionctl: %s (status %d)\n", status.error_message().c_str(),
                 static_cast<int>(status.error_code()));
  }
  return 1;
}

int Usage(const std::string& message) {
  std::fprintf(stderr, "fusionctl: %s (see fusionctl --help)\n", message.c_str());
  return 2;
}

bool ParseDouble(const std::string& text, double* value) {
  char* end = nullptr;
  *value = std::strtod(text.c_str(), &end);
  return !text.empty() && *end == '\0' && std::isfinite(*value);
}

bool ParsePoint(const std::vector<std::string>& args, std::size_t at, fusion::v1::Point* p) {
  double x, y, z;
  if (at + 3 > args.size() || !ParseDouble(args[at], &x) || !ParseDouble(args[at + 1], &y) ||
      !ParseDouble(args[at + 2], &z)) {
    return false;
  }
  p->set_x(x);
  p->set_y(y);
  p->set_z(z);
  return true;
}

const char* StateName(fusion::v1::VoxelState s) {
  switch (s) {
    case fusion::v1::VOXEL_STATE_OCCUPIED: return "occupied";
    case fusion::v1::VOXEL_STATE_FREE: return "free";
    default: return "unknown";
  }
}

// Positional arguments and --name value options of one command.
struct Args {
  std::vector<std::string> positional;
  std::multimap<std::string, std::string> options;
  std::vector<std::string> flags;
  bool Has(const std::string& f) const {
    return std::find(flags.begin(), flags.end(), f) != flags.end();
  }
  std::string Get(const std::string& name, const std::string& fallback = "") const {
    auto it = options.find(name);
    return it == options.end() ? fallback : it->second;
  }
};

// Options that take a value; the rest of --words are flags.
const char* const kValued[] = {"--state", "--limit", "--max-range", "--max", "--min-support",
                               "--color", "--azimuth", "--elevation", "--size", "--since",
                               "--count", "--min-probability"};

bool Valued(const std::string& arg) {
  return std::find(std::begin(kValued), std::end(kValued), arg) != std::end(kValued);
}

int Health(Context& ctx, const Args&) {
  auto stub = grpc::health::v1::Health::NewStub(ctx.channel);
  grpc::ClientContext context;
  SetDeadline(&context, ctx.timeout_s);
  grpc::health::v1::HealthCheckResponse reply;
  const auto status = stub->Check(&context, grpc::health::v1::HealthCheckRequest(), &reply);
  if (!status.ok()) return Failed(ctx, status);
  const bool serving = reply.status() == grpc::health::v1::HealthCheckResponse::SERVING;
  std::printf("%s\n", serving ? "SERVING" : "NOT_SERVING");
  return serving ? 0 : 1;
}

int Stats(Context& ctx, const Args&) {
  grpc::ClientContext context;
  SetDeadline(&context, ctx.timeout_s);
  fusion::v1::Stats s;
  const auto status = ctx.stub->GetStats(&context, fusion::v1::GetStatsRequest(), &s);
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
  return 0;
}

int Sensors(Context& ctx, const Args&) {
  grpc::ClientContext context;
  SetDeadline(&context, ctx.timeout_s);
  fusion::v1::ListSensorsResponse reply;
  const auto status = ctx.stub->ListSensors(&context, fusion::v1::ListSensorsRequest(), &reply);
  if (!status.ok()) return Failed(ctx, status);
  std::printf("%-12s %-8s %9s %13s %10s %10s %9s %9s %9s %10s\n", "sensor", "preset", "beams",
              "memory_bytes", "received", "integrated", "merged", "dropped", "rejected",
              "last_seq");
  for (const auto& s : reply.sensors()) {
    const auto& c = s.counters();
    std::printf("%-12s %-8s %9u %13llu %10llu %10llu %9llu %9llu %9llu %10llu\n", s.id().c_str(),
                s.preset().empty() ? "-" : s.preset().c_str(), s.beams(), (unsigned long long)s.memory_bytes(),
                (unsigned long long)c.received(), (unsigned long long)c.integrated(),
                (unsigned long long)c.merged(), (unsigned long long)c.dropped(),
                (unsigned long long)c.rejected(),
                (unsigned long long)c.last_sequence_number());
    for (const auto& [reason, count] : c.rejected_by_reason()) {
      std::printf("  rejected %-16s %llu\n", reason.c_str(), (unsigned long long)count);
    }
  }
  return 0;
}

int Points(Context& ctx, const Args& args) {
  if (args.positional.empty()) return Usage("points needs X,Y,Z arguments");
  fusion::v1::QueryPointsRequest request;
  for (const auto& text : args.positional) {
    std::vector<std::string> parts;
    std::stringstream ss(text);
    for (std::string part; std::getline(ss, part, ',');) parts.push_back(part);
    if (parts.size() != 3 || !ParsePoint(parts, 0, request.add_points())) {
      return Usage("'" + text + "' is not X,Y,Z");
    }
  }
  grpc::ClientContext context;
  SetDeadline(&context, ctx.timeout_s);
  fusion::v1::QueryPointsResponse reply;
  const auto status = ctx.stub->QueryPoints(&context, request, &reply);
  if (!status.ok()) return Failed(ctx, status);
  std::printf("# map version %llu\n", (unsigned long long)reply.map_version());
  for (int i = 0; i < reply.results_size(); ++i) {
    const auto& p = request.points(i);
    std::printf("%.3f,%.3f,%.3f  %-8s %.3f\n", p.x(), p.y(), p.z(),
                StateName(reply.results(i).state()), reply.results(i).probability());
  }
  return 0;
}

int Box(Context& ctx, const Args& args) {
  fusion::v1::QueryBoxRequest request;
  if (!ParsePoint(args.positional, 0, request.mutable_min()) ||
      !ParsePoint(args.positional, 3, request.mutable_max())) {
    return Usage("box needs MINX MINY MINZ MAXX MAXY MAXZ");
  }
  for (auto [it, end] = args.options.equal_range("--state"); it != end; ++it) {
    if (it->second == "occupied") request.add_states(fusion::v1::VOXEL_STATE_OCCUPIED);
    else if (it->second == "free") request.add_states(fusion::v1::VOXEL_STATE_FREE);
    else if (it->second == "unknown") request.add_states(fusion::v1::VOXEL_STATE_UNKNOWN);
    else return Usage("--state takes occupied, free or unknown");
  }
  const long limit = std::atol(args.Get("--limit", "100000").c_str());
  long printed = 0;
  std::map<std::string, long> by_state;
  do {
    grpc::ClientContext context;
    SetDeadline(&context, ctx.timeout_s);
    fusion::v1::QueryBoxResponse reply;
    const auto status = ctx.stub->QueryBox(&context, request, &reply);
    if (!status.ok()) return Failed(ctx, status);
    for (const auto& v : reply.voxels()) {
      if (printed++ >= limit) break;
      by_state[StateName(v.state())]++;
      std::printf("%.3f %.3f %.3f %.3f %-8s %.3f\n", v.center().x(), v.center().y(),
                  v.center().z(), v.size_m(), StateName(v.state()), v.probability());
    }
    request.set_page_token(reply.next_page_token());
  } while (!request.page_token().empty() && printed < limit);
  std::fprintf(stderr, "# %ld voxels", printed);
  for (const auto& [state, n] : by_state) std::fprintf(stderr, ", %ld %s", n, state.c_str());
  std::fprintf(stderr, "%s\n", printed >= limit ? " (limit reached)" : "");
  return 0;
}

int Ray(Context& ctx, const Args& args) {
  fusion::v1::CastRayRequest request;
  if (!ParsePoint(args.positional, 0, request.mutable_origin()) ||
      !ParsePoint(args.positional, 3, request.mutable_direction())) {
    return Usage("ray needs OX OY OZ DX DY DZ");
  }
  double max_range_m = 10.0;
  if (!ParseDouble(args.Get("--max-range", "10"), &max_range_m)) return Usage("bad --max-range");
  request.set_max_range_m(max_range_m);
  request.set_ignore_unknown(args.Has("--ignore-unknown"));
  grpc::ClientContext context;
  SetDeadline(&context, ctx.timeout_s);
  fusion::v1::CastRayResponse reply;
  const auto status = ctx.stub->CastRay(&context, request, &reply);
  if (!status.ok()) return Failed(ctx, status);
  std::printf("%s at %.3f %.3f %.3f, range %.3f m (stopped at %s voxel)\n",
              reply.hit() ? "hit" : "no hit", reply.end().x(), reply.end().y(), reply.end().z(),
              reply.range_m(), StateName(reply.stopped_at()));
  return 0;
}

int Planes(Context& ctx, const Args& args) {
  fusion::v1::FindPlanesRequest request;
  request.set_max_planes(static_cast<unsigned>(std::atoi(args.Get("--max", "8").c_str())));
  if (!args.Get("--min-support").empty()) {
    request.set_min_support_voxels(
        static_cast<unsigned>(std::atoi(args.Get("--min-support").c_str())));
  }
  if (args.Has("--region")) {
    if (!ParsePoint(args.positional, 0, request.mutable_region_min()) ||
        !ParsePoint(args.positional, 3, request.mutable_region_max())) {
      return Usage("--region needs MINX MINY MINZ MAXX MAXY MAXZ");
    }
  }
  grpc::ClientContext context;
  SetDeadline(&context, std::max(ctx.timeout_s, 60.0));  // an expensive call, like snapshots
  fusion::v1::FindPlanesResponse reply;
  const auto status = ctx.stub->FindPlanes(&context, request, &reply);
  if (!status.ok()) return Failed(ctx, status);
  std::printf("# map version %llu: %d planes\n", (unsigned long long)reply.map_version(),
              reply.planes_size());
  std::printf("%7s %7s %8s  %-24s %8s %8s  %s\n", "phi", "theta", "d_m", "normal", "support",
              "rms_mm", "extent (m)");
  for (const auto& p : reply.planes()) {
    std::printf("%7.2f %7.2f %8.4f  (%6.3f,%6.3f,%6.3f) %8llu %8.1f  [%.2f %.2f %.2f]..[%.2f %.2f %.2f]\n",
                p.phi_deg(), p.theta_deg(), p.d_m(), p.normal().x(), p.normal().y(),
                p.normal().z(), (unsigned long long)p.support_voxels(), p.rms_m() * 1000.0,
                p.extent_min().x(), p.extent_min().y(), p.extent_min().z(), p.extent_max().x(),
                p.extent_max().y(), p.extent_max().z());
  }
  return 0;
}

// Fetches the whole snapshot; *version receives the map version.
bool FetchSnapshot(Context& ctx, fusion::v1::GetSnapshotRequest::Format format,
                   std::string* bytes, unsigned long long* version, int* rc) {
  grpc::ClientContext context;
  SetDeadline(&context, std::max(ctx.timeout_s, 60.0));
  fusion::v1::GetSnapshotRequest request;
  request.set_format(format);
  auto reader = ctx.stub->GetSnapshot(&context, request);
  fusion::v1::SnapshotChunk chunk;
  while (reader->Read(&chunk)) {
    if (chunk.offset() != bytes->size()) {
      std::fprintf(stderr, "fusionctl: snapshot chunk out of order\n");
      context.TryCancel();
      *rc = 1;
      return false;
    }
    bytes->append(chunk.data());
    *version = chunk.map_version();
    if (chunk.total_bytes() > 0 && isatty(2)) {
      std::fprintf(stderr, "\rsnapshot: %zu / %llu bytes", bytes->size(),
                   (unsigned long long)chunk.total_bytes());
    }
  }
  if (isatty(2)) std::fprintf(stderr, "\n");
  const auto status = reader->Finish();
  if (!status.ok()) {
    *rc = Failed(ctx, status);
    return false;
  }
  return true;
}

int Snapshot(Context& ctx, const Args& args) {
  if (args.positional.size() != 1) return Usage("snapshot needs FILE.bt or FILE.ot");
  const std::string& path = args.positional[0];
  const bool bt = path.size() > 3 && path.compare(path.size() - 3, 3, ".bt") == 0;
  const bool ot = path.size() > 3 && path.compare(path.size() - 3, 3, ".ot") == 0;
  if (!bt && !ot) return Usage("snapshot file must end in .bt or .ot");
  std::string bytes;
  unsigned long long version = 0;
  int rc = 0;
  if (!FetchSnapshot(ctx, bt ? fusion::v1::GetSnapshotRequest::FORMAT_BT
                             : fusion::v1::GetSnapshotRequest::FORMAT_OT,
                     &bytes, &version, &rc)) {
    return rc;
  }
  std::ofstream out(path, std::ios::binary);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  if (!out.flush()) {
    std::fprintf(stderr, "fusionctl: cannot write '%s'\n", path.c_str());
    return 1;
  }
  std::printf("wrote %s: %zu bytes, map version %llu\n", path.c_str(), bytes.size(), version);
  return 0;
}

int Render(Context& ctx, const Args& args) {
  if (args.positional.size() != 1) return Usage("render needs FILE.png");
  fusion::render::RenderOptions options;
  const std::string color = args.Get("--color", "height");
  if (color == "height") options.color_by = fusion::render::ColorBy::kHeight;
  else if (color == "probability") options.color_by = fusion::render::ColorBy::kProbability;
  else return Usage("--color takes height or probability");
  if (!args.Get("--azimuth").empty() &&
      !ParseDouble(args.Get("--azimuth"), &options.view_azimuth_deg)) {
    return Usage("bad --azimuth");
  }
  if (!args.Get("--elevation").empty() &&
      !ParseDouble(args.Get("--elevation"), &options.view_elevation_deg)) {
    return Usage("bad --elevation");
  }
  if (!args.Get("--min-probability").empty() &&
      !ParseDouble(args.Get("--min-probability"), &options.min_probability)) {
    return Usage("bad --min-probability");
  }
  if (!args.Get("--size").empty() &&
      std::sscanf(args.Get("--size").c_str(), "%dx%d", &options.width_px, &options.height_px) != 2) {
    return Usage("--size takes WxH");
  }
  if (options.width_px <= 0 || options.height_px <= 0 || options.width_px > 8192 ||
      options.height_px > 8192) {
    return Usage("--size must be between 1x1 and 8192x8192");
  }
  std::string bytes;
  unsigned long long version = 0;
  int rc = 0;
  if (!FetchSnapshot(ctx, fusion::v1::GetSnapshotRequest::FORMAT_OT, &bytes, &version, &rc)) {
    return rc;
  }
  std::istringstream in(bytes);
  std::unique_ptr<octomap::AbstractOcTree> tree(octomap::AbstractOcTree::read(in));
  auto* octree = dynamic_cast<octomap::OcTree*>(tree.get());
  if (!octree) {
    std::fprintf(stderr, "fusionctl: the snapshot is not an OcTree\n");
    return 1;
  }
  const auto image = fusion::render::RenderOccupied(*octree, options);
  std::string error;
  if (!fusion::render::WritePng(args.positional[0], image, &error)) {
    std::fprintf(stderr, "fusionctl: %s\n", error.c_str());
    return 1;
  }
  std::printf("wrote %s: %dx%d, %zu occupied voxels drawn, map version %llu\n",
              args.positional[0].c_str(), image.width, image.height, image.voxels_drawn, version);
  return 0;
}

int Watch(Context& ctx, const Args& args) {
  fusion::v1::StreamUpdatesRequest request;
  request.set_since_version(std::strtoull(args.Get("--since", "0").c_str(), nullptr, 10));
  const bool versions_only = args.Has("--versions-only");
  request.set_versions_only(versions_only);
  const long count = std::atol(args.Get("--count", "0").c_str());
  grpc::ClientContext context;
  auto reader = ctx.stub->StreamUpdates(&context, request);
  fusion::v1::MapUpdate update;
  long versions = 0;
  std::size_t voxels = 0;
  while (reader->Read(&update)) {
    voxels += static_cast<std::size_t>(update.voxels_size());
    if (!update.complete()) continue;
    if (versions_only) {
      std::printf("version %llu (from %llu)\n", (unsigned long long)update.map_version(),
                  (unsigned long long)update.from_version());
    } else {
      std::printf("version %llu (from %llu)%s: %zu voxels changed\n",
                  (unsigned long long)update.map_version(),
                  (unsigned long long)update.from_version(), update.full() ? " full" : "",
                  voxels);
    }
    std::fflush(stdout);
    voxels = 0;
    if (count > 0 && ++versions >= count) {
      context.TryCancel();
      break;
    }
  }
  const auto status = reader->Finish();
  if (!status.ok() && status.error_code() != grpc::StatusCode::CANCELLED) {
    return Failed(ctx, status);
  }
  return 0;
}

int Beam(Context& ctx, const Args& args) {
  if (args.positional.size() != 3) return Usage("beam needs SENSOR ROW COL");
  fusion::v1::InspectBeamRequest request;
  request.set_sensor_id(args.positional[0]);
  request.set_row(static_cast<unsigned>(std::atoi(args.positional[1].c_str())));
  request.set_col(static_cast<unsigned>(std::atoi(args.positional[2].c_str())));
  grpc::ClientContext context;
  SetDeadline(&context, ctx.timeout_s);
  fusion::v1::InspectBeamResponse reply;
  const auto status = ctx.stub->InspectBeam(&context, request, &reply);
  if (!status.ok()) return Failed(ctx, status);
  std::printf("# beam %u, direction (%.4f, %.4f, %.4f), %s, cell %.4f m\n", reply.beam(),
              reply.direction().x(), reply.direction().y(), reply.direction().z(),
              reply.touched() ? "touched" : "untouched", reply.cell_size_m());
  std::printf("%8s %10s %14s %10s\n", "cell", "range_m", "p(B)", "p(m)");
  // Only the cells that carry information, so the table stays readable at 1 mm cells.
  const int n = reply.cell_occupancy_size();
  for (int i = 0; i < n; ++i) {
    const double pb = reply.first_hit(i);
    if (pb < 1e-4 && std::abs(reply.cell_occupancy(i) - reply.cell_occupancy(0)) < 1e-3 &&
        reply.cell_occupancy(i) < 0.5) {
      continue;
    }
    std::printf("%8d %10.4f %14.6g %10.4f\n", i + 1, (i + 0.5) * reply.cell_size_m(), pb,
                reply.cell_occupancy(i));
  }
  if (reply.first_hit_size() == n + 1) {
    std::printf("%8s %10s %14.6g\n", "N+1", "beyond", reply.first_hit(n));
  }
  return 0;
}

int Reset(Context& ctx, const Args&) {
  grpc::ClientContext context;
  SetDeadline(&context, ctx.timeout_s);
  fusion::v1::ResetMapResponse reply;
  const auto status = ctx.stub->ResetMap(&context, fusion::v1::ResetMapRequest(), &reply);
  if (!status.ok()) return Failed(ctx, status);
  std::printf("map reset, version %llu\n", (unsigned long long)reply.map_version());
  return 0;
}

int Save(Context& ctx, const Args&) {
  grpc::ClientContext context;
  SetDeadline(&context, ctx.timeout_s);
  fusion::v1::SaveMapResponse reply;
  const auto status = ctx.stub->SaveMap(&context, fusion::v1::SaveMapRequest(), &reply);
  if (!status.ok()) return Failed(ctx, status);
  std::printf("saved %s: %llu bytes, map version %llu\n", reply.path().c_str(),
              (unsigned long long)reply.bytes(), (unsigned long long)reply.map_version());
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  Context ctx;
  const char* env_address = std::getenv("FUSIOND_ADDRESS");
  ctx.server = env_address && *env_address ? env_address : "127.0.0.1:50051";
  bool timeout_given = false;
  std::string command;
  Args args;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    if (arg == "--help" || arg == "-h" || (command.empty() && arg == "help")) {
      std::fputs(kUsage, stdout);
      return 0;
    } else if (arg == "--server" || arg == "--timeout") {
      if (i + 1 >= argc) return Usage(arg + " needs a value");
      const std::string value = argv[++i];
      if (arg == "--server") {
        ctx.server = value;
      } else if (!ParseDouble(value, &ctx.timeout_s) || ctx.timeout_s <= 0) {
        return Usage("--timeout takes a positive number of seconds");
      } else {
        timeout_given = true;
      }
    } else if (command.empty() && arg.rfind("--", 0) != 0) {
      command = arg;
    } else if (Valued(arg)) {
      if (i + 1 >= argc) return Usage(arg + " needs a value");
      args.options.emplace(arg, argv[++i]);
    } else if (arg.rfind("--", 0) == 0 && !(arg.size() > 2 && std::isdigit(arg[2]))) {
      args.flags.push_back(arg);
    } else {
      args.positional.push_back(arg);
    }
  }
  (void)timeout_given;
  if (command.empty()) {
    std::fputs(kUsage, stderr);
    return 2;
  }
  static const std::map<std::string, std::function<int(Context&, const Args&)>> kCommands = {
      {"health", Health}, {"stats", Stats},       {"sensors", Sensors}, {"points", Points},
      {"box", Box},       {"ray", Ray},           {"planes", Planes},   {"snapshot", Snapshot},
      {"render", Render}, {"watch", Watch},       {"beam", Beam},       {"reset", Reset},
      {"save", Save}};
  const auto it = kCommands.find(command);
  if (it == kCommands.end()) return Usage("unknown command '" + command + "'");
  ctx.channel = grpc::CreateChannel(ctx.server, grpc::InsecureChannelCredentials());
  ctx.stub = FusionMap::NewStub(ctx.channel);
  return it->second(ctx, args);
}
