// fusionctl: command-line client of fusiond. Speaks only the wire types (proto/). This file:
// the global options and the dispatch to the commands (fusionctl.h).
#include <cctype>
#include <cstdio>
#include <cstdlib>
#include <functional>
#include <iterator>
#include <map>
#include <optional>
#include <string>

#include "fusionctl.h"

namespace fusionctl {
namespace {

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

// Options that take a value; the rest of --words are flags.
const char* const kValued[] = {"--state",       "--limit", "--max-range", "--max",
                               "--min-support", "--color", "--azimuth",   "--elevation",
                               "--size",        "--since", "--count",     "--min-probability"};

bool Valued(const std::string& arg) {
  return std::find(std::begin(kValued), std::end(kValued), arg) != std::end(kValued);
}

// Splits the command line into the global options (into ctx), the command and its arguments.
// Returns the exit code when fusionctl is done already (--help, a bad command line).
std::optional<int> ParseCommandLine(int argc, char** argv, Context* ctx, std::string* command,
                                    Args* args) {
  const char* env_address = std::getenv("FUSIOND_ADDRESS");
  ctx->server = env_address && *env_address ? env_address : "127.0.0.1:50051";
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    std::string value;
    if (fusion::clients::IsHelpFlag(arg) || (command->empty() && arg == "help")) {
      return fusion::clients::PrintHelp(kUsage);
    } else if (arg == "--server" || arg == "--timeout") {
      if (!fusion::clients::TakeValue(argc, argv, &i, &value)) {
        return Usage(arg + " needs a value");
      }
      if (arg == "--server") {
        ctx->server = value;
      } else if (!fusion::clients::ParseFinite(value, &ctx->timeout_s) || ctx->timeout_s <= 0) {
        return Usage("--timeout takes a positive number of seconds");
      }
    } else if (command->empty() && arg.rfind("--", 0) != 0) {
      *command = arg;
    } else if (Valued(arg)) {
      if (!fusion::clients::TakeValue(argc, argv, &i, &value)) {
        return Usage(arg + " needs a value");
      }
      args->options.emplace(arg, value);
    } else if (arg.rfind("--", 0) == 0 && !(arg.size() > 2 && std::isdigit(arg[2]))) {
      args->flags.push_back(arg);
    } else {
      args->positional.push_back(arg);
    }
  }
  if (command->empty()) {
    std::fputs(kUsage, stderr);
    return fusion::clients::kExitUsage;
  }
  return std::nullopt;
}

}  // namespace
}  // namespace fusionctl

int main(int argc, char** argv) {
  using namespace fusionctl;
  Context ctx;
  std::string command;
  Args args;
  if (const auto done = ParseCommandLine(argc, argv, &ctx, &command, &args)) return *done;
  static const std::map<std::string, std::function<int(Context&, const Args&)>> kCommands = {
      {"health", Health}, {"stats", Stats}, {"sensors", Sensors}, {"points", Points},
      {"box", Box},       {"ray", Ray},     {"planes", Planes},   {"snapshot", Snapshot},
      {"render", Render}, {"watch", Watch}, {"beam", Beam},       {"reset", Reset},
      {"save", Save}};
  const auto it = kCommands.find(command);
  if (it == kCommands.end()) return Usage("unknown command '" + command + "'");
  ctx.channel = grpc::CreateChannel(ctx.server, grpc::InsecureChannelCredentials());
  ctx.stub = fusion::v1::FusionMap::NewStub(ctx.channel);
  return it->second(ctx, args);
}
