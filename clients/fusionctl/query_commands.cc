// fusionctl points, box, ray, planes and beam: questions about places in the map.
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <sstream>

#include "fusionctl.h"

namespace fusionctl {

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
  fusion::v1::QueryPointsResponse reply;
  const auto status = Call(ctx, &Stub::QueryPoints, request, &reply);
  if (!status.ok()) return Failed(ctx, status);
  if (ctx.json) {
    PrintJson(reply);
    return fusion::clients::kExitOk;
  }
  std::printf("# map version %llu\n", (unsigned long long)reply.map_version());
  for (int i = 0; i < reply.results_size(); ++i) {
    const auto& p = request.points(i);
    std::printf("%.3f,%.3f,%.3f  %-8s %.3f\n", p.x(), p.y(), p.z(),
                StateName(reply.results(i).state()), reply.results(i).probability());
  }
  return fusion::clients::kExitOk;
}

int Box(Context& ctx, const Args& args) {
  fusion::v1::QueryBoxRequest request;
  if (!ParsePoint(args.positional, 0, request.mutable_min()) ||
      !ParsePoint(args.positional, 3, request.mutable_max())) {
    return Usage("box needs MINX MINY MINZ MAXX MAXY MAXZ");
  }
  for (auto [it, end] = args.options.equal_range("--state"); it != end; ++it) {
    if (it->second == "occupied")
      request.add_states(fusion::v1::VOXEL_STATE_OCCUPIED);
    else if (it->second == "free")
      request.add_states(fusion::v1::VOXEL_STATE_FREE);
    else if (it->second == "unknown")
      request.add_states(fusion::v1::VOXEL_STATE_UNKNOWN);
    else
      return Usage("--state takes occupied, free or unknown");
  }
  unsigned long long limit = 0;
  if (!OptionUint(args, "--limit", 100000, &limit)) return Usage("--limit takes a count");
  unsigned long long printed = 0;
  bool more = false;  // voxels left over past the limit
  std::map<std::string, unsigned long long> by_state;
  // --json: the pages gathered into one QueryBoxResponse (next_page_token empty).
  fusion::v1::QueryBoxResponse gathered;
  do {
    fusion::v1::QueryBoxResponse reply;
    const auto status = Call(ctx, &Stub::QueryBox, request, &reply);
    if (!status.ok()) return Failed(ctx, status);
    if (printed == 0) gathered.set_map_version(reply.map_version());
    for (const auto& v : reply.voxels()) {
      if (printed >= limit) {
        more = true;
        break;
      }
      ++printed;
      by_state[StateName(v.state())]++;
      if (ctx.json) {
        *gathered.add_voxels() = v;
      } else {
        std::printf("%.3f %.3f %.3f %.3f %-8s %.3f\n", v.center().x(), v.center().y(),
                    v.center().z(), v.size_m(), StateName(v.state()), v.probability());
      }
    }
    request.set_page_token(reply.next_page_token());
  } while (!request.page_token().empty() && !more);
  if (ctx.json) PrintJson(gathered);
  std::fprintf(stderr, "# %llu voxels", printed);
  for (const auto& [state, n] : by_state) std::fprintf(stderr, ", %llu %s", n, state.c_str());
  std::fprintf(stderr, "%s\n", more || !request.page_token().empty() ? " (limit reached)" : "");
  return fusion::clients::kExitOk;
}

int Ray(Context& ctx, const Args& args) {
  fusion::v1::CastRayRequest request;
  if (!ParsePoint(args.positional, 0, request.mutable_origin()) ||
      !ParsePoint(args.positional, 3, request.mutable_direction())) {
    return Usage("ray needs OX OY OZ DX DY DZ");
  }
  double max_range_m = 10.0;
  if (!fusion::clients::ParseFinite(args.Get("--max-range", "10"), &max_range_m))
    return Usage("bad --max-range");
  request.set_max_range_m(max_range_m);
  request.set_ignore_unknown(args.Has("--ignore-unknown"));
  fusion::v1::CastRayResponse reply;
  const auto status = Call(ctx, &Stub::CastRay, request, &reply);
  if (!status.ok()) return Failed(ctx, status);
  if (ctx.json) {
    PrintJson(reply);
    return fusion::clients::kExitOk;
  }
  std::printf("%s at %.3f %.3f %.3f, range %.3f m (stopped at %s voxel)\n",
              reply.hit() ? "hit" : "no hit", reply.end().x(), reply.end().y(), reply.end().z(),
              reply.range_m(), StateName(reply.stopped_at()));
  return fusion::clients::kExitOk;
}

int Planes(Context& ctx, const Args& args) {
  fusion::v1::FindPlanesRequest request;
  unsigned long long max_planes = 0, min_support = 0;
  if (!OptionUint(args, "--max", 8, &max_planes) || max_planes > 64) {
    return Usage("--max takes a count, 0..64");
  }
  // 0: the service's default.
  if (!OptionUint(args, "--min-support", 0, &min_support) || min_support > 0xffffffffull) {
    return Usage("--min-support takes a count of voxels");
  }
  request.set_max_planes(static_cast<unsigned>(max_planes));
  request.set_min_support_voxels(static_cast<unsigned>(min_support));
  if (args.Has("--region")) {
    if (!ParsePoint(args.positional, 0, request.mutable_region_min()) ||
        !ParsePoint(args.positional, 3, request.mutable_region_max())) {
      return Usage("--region needs MINX MINY MINZ MAXX MAXY MAXZ");
    }
  }
  fusion::v1::FindPlanesResponse reply;
  // An expensive call, like snapshots: its default --timeout is longer (command_line.cc).
  const auto status = Call(ctx, &Stub::FindPlanes, request, &reply);
  if (!status.ok()) return Failed(ctx, status);
  if (ctx.json) {
    PrintJson(reply);
    return fusion::clients::kExitOk;
  }
  std::printf("# map version %llu: %d planes\n", (unsigned long long)reply.map_version(),
              reply.planes_size());
  // Angles to 0.01 degree and the normal to 1e-6 (0.01 degree is 1.7e-4 of a unit vector),
  // so a 1-degree tilt reads in every column.
  std::printf("%8s %9s %8s  %-31s %8s %8s  %s\n", "phi_deg", "theta_deg", "d_m", "normal",
              "support", "rms_mm", "extent (m)");
  for (const auto& p : reply.planes()) {
    std::printf(
        "%8.2f %9.2f %8.4f  (%9.6f,%9.6f,%9.6f) %8llu %8.1f  [%.2f %.2f %.2f]..[%.2f %.2f %.2f]\n",
        p.phi_deg(), p.theta_deg(), p.d_m(), p.normal().x(), p.normal().y(), p.normal().z(),
        (unsigned long long)p.support_voxels(), p.rms_m() * 1000.0, p.extent_min().x(),
        p.extent_min().y(), p.extent_min().z(), p.extent_max().x(), p.extent_max().y(),
        p.extent_max().z());
  }
  return fusion::clients::kExitOk;
}

int Beam(Context& ctx, const Args& args) {
  if (args.positional.size() != 3) return Usage("beam needs SENSOR ROW COL");
  fusion::v1::InspectBeamRequest request;
  request.set_sensor_id(args.positional[0]);
  std::uint64_t row = 0, col = 0;
  if (!fusion::clients::ParseUint("ROW", args.positional[1], &row).ok() ||
      !fusion::clients::ParseUint("COL", args.positional[2], &col).ok() || row > 0xffffffffull ||
      col > 0xffffffffull) {
    return Usage("beam: ROW and COL are beam indices (0, 1, ...)");
  }
  request.set_row(static_cast<unsigned>(row));
  request.set_col(static_cast<unsigned>(col));
  fusion::v1::InspectBeamResponse reply;
  const auto status = Call(ctx, &Stub::InspectBeam, request, &reply);
  if (!status.ok()) return Failed(ctx, status);
  if (ctx.json) {
    PrintJson(reply);
    return fusion::clients::kExitOk;
  }
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
  return fusion::clients::kExitOk;
}

}  // namespace fusionctl
