// fusionctl's command line: global options anywhere, then each command's own options checked
// against its list, so a typo (`reset --yes-really`) is an error instead of a silent default.
#include "command_line.h"

#include <cstdio>
#include <cstdlib>

namespace fusionctl {
namespace {

constexpr const char* kGlobalUsage = R"(fusionctl: command-line client of fusiond

Usage: fusionctl [GLOBAL OPTIONS] COMMAND [ARGS] [OPTIONS]
       fusionctl COMMAND --help       a command's own arguments and options

Global options (anywhere on the line):
  --server HOST:PORT   fusiond's gRPC address (default $FUSIOND_ADDRESS or 127.0.0.1:50051)
  --timeout SECONDS    deadline of each call (default 10; planes, snapshot, render: 120;
                       watch: none)
  --json               one JSON document per result on stdout (schema: docs/clients.md)
  --tls-ca FILE        TLS with these PEM root certificates ($FUSION_TLS_CA)
  --tls-cert FILE      client certificate for mutual TLS, with --tls-key ($FUSION_TLS_CERT)
  --tls-key FILE       the client certificate's private key ($FUSION_TLS_KEY)
  --token-file FILE    send "authorization: Bearer <first line of FILE>" ($FUSION_TOKEN_FILE)

Commands:
  health      grpc.health.v1 check; exit 0 when SERVING
  stats       map version, counters (clouds_in_map among them), memory
  sensors     configured sensors and their ingest counters
  points      occupancy of points
  box         voxels in a box
  ray         first occupied voxel along a ray
  planes      planes found by the Hough transform
  snapshot    write the map in OctoMap's format
  render      a PNG picture of the occupied voxels
  watch       stream map updates
  beam        p(B) and p(m) of one beam
  reset       clear the map and every beam grid
  clear-box   forget a box of the map (its voxels become unknown)
  save        write a snapshot to the service's persistence path
  help        this text

Exit codes: 0 done, 1 the call or a file failed, 2 a bad command line.
)";

constexpr double kCallTimeoutS = 10.0;
// Hough transforms and whole-map snapshots run on fusiond's low-priority pool: on a busy or
// sanitized service they take tens of seconds.
constexpr double kHeavyCallTimeoutS = 120.0;

constexpr const char* kHealthUsage =
    "Usage: fusionctl health\n  grpc.health.v1 check; exit 0 when SERVING\n";
constexpr const char* kStatsUsage =
    "Usage: fusionctl stats\n  every field of fusion.v1.Stats: map version, cloud counters "
    "(clouds_in_map: clouds\n  the map that queries see holds), memory, snapshots, uptime\n";
constexpr const char* kSensorsUsage =
    "Usage: fusionctl sensors\n  configured sensors and their ingest counters\n";
constexpr const char* kPointsUsage =
    "Usage: fusionctl points X,Y,Z [X,Y,Z ...]\n  occupancy state and probability of points "
    "(world frame, metres)\n";
constexpr const char* kBoxUsage =
    "Usage: fusionctl box MINX MINY MINZ MAXX MAXY MAXZ [--state occupied|free|unknown]...\n"
    "                    [--limit N]\n"
    "  voxels in a box (metres), all pages, at most --limit (default 100000); the summary\n"
    "  line goes to stderr\n";
constexpr const char* kRayUsage =
    "Usage: fusionctl ray OX OY OZ DX DY DZ [--max-range M] [--ignore-unknown]\n"
    "  first occupied voxel along a ray (default --max-range 10 m)\n";
constexpr const char* kPlanesUsage =
    "Usage: fusionctl planes [--max N] [--min-support N] [--region MINX MINY MINZ MAXX MAXY "
    "MAXZ]\n"
    "  planes found by the Hough transform: phi, theta (0.01 degree), d, the unit normal,\n"
    "  support voxels, rms, extent\n";
constexpr const char* kSnapshotUsage =
    "Usage: fusionctl snapshot FILE.bt|FILE.ot\n  write the map in OctoMap's format (by "
    "extension)\n";
constexpr const char* kRenderUsage =
    "Usage: fusionctl render FILE.png [--color height|probability] [--azimuth DEG]\n"
    "                        [--elevation DEG] [--size WxH] [--min-probability P]\n"
    "  a PNG picture of the occupied voxels (other extensions are refused)\n";
constexpr const char* kWatchUsage =
    "Usage: fusionctl watch [--since VERSION] [--count N] [--versions-only]\n"
    "  stream map updates (Ctrl-C to stop; --count: after N versions); --versions-only:\n"
    "  announce new versions without their voxels\n";
constexpr const char* kBeamUsage =
    "Usage: fusionctl beam SENSOR ROW COL\n  p(B) and p(m) of one beam, as a table\n";
constexpr const char* kResetUsage = "Usage: fusionctl reset\n  clear the map and every beam grid\n";
constexpr const char* kClearBoxUsage =
    "Usage: fusionctl clear-box MINX MINY MINZ MAXX MAXY MAXZ\n"
    "  forget what the map knows in a box (world frame, metres): its voxels become unknown,\n"
    "  every sensor's period restarts (an admin call where tokens are configured)\n";
constexpr const char* kSaveUsage =
    "Usage: fusionctl save\n  write a snapshot to the service's persistence path\n";

// name, run, usage, valued options, flags, min and max arguments, default deadline.
const std::vector<CommandSpec> kCommands = {
    {"health", Health, kHealthUsage, {}, {}, 0, 0, kCallTimeoutS},
    {"stats", Stats, kStatsUsage, {}, {}, 0, 0, kCallTimeoutS},
    {"sensors", Sensors, kSensorsUsage, {}, {}, 0, 0, kCallTimeoutS},
    {"points", Points, kPointsUsage, {}, {}, 1, 100000, kCallTimeoutS},
    {"box", Box, kBoxUsage, {"--state", "--limit"}, {}, 6, 6, kCallTimeoutS},
    {"ray", Ray, kRayUsage, {"--max-range"}, {"--ignore-unknown"}, 6, 6, kCallTimeoutS},
    {"planes",
     Planes,
     kPlanesUsage,
     {"--max", "--min-support"},
     {"--region"},
     0,
     6,
     kHeavyCallTimeoutS},
    {"snapshot", Snapshot, kSnapshotUsage, {}, {}, 1, 1, kHeavyCallTimeoutS},
    {"render",
     Render,
     kRenderUsage,
     {"--color", "--azimuth", "--elevation", "--size", "--min-probability"},
     {},
     1,
     1,
     kHeavyCallTimeoutS},
    {"watch", Watch, kWatchUsage, {"--since", "--count"}, {"--versions-only"}, 0, 0, 0.0},
    {"beam", Beam, kBeamUsage, {}, {}, 3, 3, kCallTimeoutS},
    {"reset", Reset, kResetUsage, {}, {}, 0, 0, kCallTimeoutS},
    {"clear-box", ClearBox, kClearBoxUsage, {}, {}, 6, 6, kCallTimeoutS},
    {"save", Save, kSaveUsage, {}, {}, 0, 0, kCallTimeoutS},
};

bool Contains(const std::vector<std::string>& list, const std::string& s) {
  return std::find(list.begin(), list.end(), s) != list.end();
}

// An argument that starts with '-' is an option unless it is a number ("-1.5" is a coordinate).
bool LooksLikeOption(const std::string& arg) {
  double unused = 0;
  return arg.size() > 1 && arg[0] == '-' && !fusion::clients::ParseFinite(arg, &unused);
}

const CommandSpec* FindCommand(const std::string& name) {
  for (const auto& spec : kCommands) {
    if (name == spec.name) return &spec;
  }
  return nullptr;
}

// A global option at argv[*i] (and its value): true when it was one; *rc set on a bad value.
bool TakeGlobalOption(int argc, char** argv, int* i, Context* ctx, bool* timeout_given,
                      std::optional<int>* rc) {
  const std::string arg = argv[*i];
  if (arg == "--json") {
    ctx->json = true;
    return true;
  }
  std::string* target = arg == "--server"       ? &ctx->connection.server
                        : arg == "--tls-ca"     ? &ctx->connection.tls_ca_path
                        : arg == "--tls-cert"   ? &ctx->connection.tls_cert_path
                        : arg == "--tls-key"    ? &ctx->connection.tls_key_path
                        : arg == "--token-file" ? &ctx->connection.token_file_path
                                                : nullptr;
  if (target == nullptr && arg != "--timeout") return false;
  std::string value;
  if (!fusion::clients::TakeValue(argc, argv, i, &value)) {
    *rc = Usage(arg + " needs a value");
  } else if (target != nullptr) {
    *target = value;
  } else if (!fusion::clients::ParseFinite(value, &ctx->timeout_s) || ctx->timeout_s <= 0) {
    *rc = Usage("--timeout takes a positive number of seconds");
  } else {
    *timeout_given = true;
  }
  return true;
}

// "fusionctl box: <message> (see fusionctl box --help)"; returns kExitUsage.
int CommandUsage(const CommandSpec& spec, const std::string& message) {
  return fusion::clients::UsageError(std::string(kTool) + " " + spec.name, message);
}

// The command's arity, after parsing: planes takes its 6 numbers only after --region.
std::optional<int> CheckArity(const CommandSpec& spec, const Args& args) {
  const std::size_t n = args.positional.size();
  const std::string name = spec.name;
  if (name == "planes" && n != (args.Has("--region") ? 6u : 0u)) {
    return CommandUsage(spec, args.Has("--region")
                                  ? "--region needs MINX MINY MINZ MAXX MAXY MAXZ"
                                  : "unexpected argument '" + args.positional[0] + "'");
  }
  if (n < spec.min_positional) return CommandUsage(spec, "missing arguments");
  if (n > spec.max_positional) {
    return CommandUsage(spec, "unexpected argument '" + args.positional[spec.max_positional] + "'");
  }
  return std::nullopt;
}

}  // namespace

const std::vector<CommandSpec>& Commands() { return kCommands; }
const char* GlobalUsage() { return kGlobalUsage; }

std::optional<int> ParseCommandLine(int argc, char** argv, Context* ctx,
                                    const CommandSpec** command, Args* args) {
  const char* env_address = std::getenv("FUSIOND_ADDRESS");
  ctx->connection.server = env_address && *env_address ? env_address : "127.0.0.1:50051";
  *command = nullptr;
  bool timeout_given = false;
  bool help = false;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    std::optional<int> rc;
    if (TakeGlobalOption(argc, argv, &i, ctx, &timeout_given, &rc)) {
      if (rc) return rc;
    } else if (fusion::clients::IsHelpFlag(arg)) {
      help = true;
    } else if (*command == nullptr && !LooksLikeOption(arg)) {
      if (arg == "help") return fusion::clients::PrintHelp(kGlobalUsage);
      *command = FindCommand(arg);
      if (*command == nullptr) return Usage("unknown command '" + arg + "'");
    } else if (*command == nullptr) {
      return Usage("unknown option " + arg);
    } else if (Contains((*command)->valued_options, arg)) {
      std::string value;
      if (!fusion::clients::TakeValue(argc, argv, &i, &value)) {
        return CommandUsage(**command, arg + " needs a value");
      }
      args->options.emplace(arg, value);
    } else if (Contains((*command)->flags, arg)) {
      args->flags.push_back(arg);
    } else if (LooksLikeOption(arg)) {
      return CommandUsage(**command, "unknown option " + arg);
    } else {
      args->positional.push_back(arg);
    }
  }
  if (help) return fusion::clients::PrintHelp(*command ? (*command)->usage : kGlobalUsage);
  if (*command == nullptr) {
    std::fputs(kGlobalUsage, stderr);
    return fusion::clients::kExitUsage;
  }
  if (!timeout_given) ctx->timeout_s = (*command)->default_timeout_s;
  if (auto rc = CheckArity(**command, *args)) return rc;
  ApplyEnvironment(&ctx->connection);
  if (auto s = CheckConnectionOptions(ctx->connection); !s.ok()) return Usage(s.message());
  return std::nullopt;
}

int Run(int argc, char** argv) {
  Context ctx;
  const CommandSpec* command = nullptr;
  Args args;
  if (const auto done = ParseCommandLine(argc, argv, &ctx, &command, &args)) return *done;
  if (!ctx.connection.token_file_path.empty()) {
    const auto s = ReadBearerToken(ctx.connection.token_file_path, &ctx.bearer_token);
    if (!s.ok()) return fusion::clients::Fail(kTool, s.message());
  }
  if (const auto s = MakeChannel(ctx.connection, &ctx.channel); !s.ok()) {
    return fusion::clients::Fail(kTool, s.message());
  }
  ctx.stub = fusion::v1::FusionMap::NewStub(ctx.channel);
  return command->run(ctx, args);
}

}  // namespace fusionctl
