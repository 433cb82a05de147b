// fusionctl's pieces: the call context, a command's arguments and the commands, grouped by file
// (status_commands.cc, query_commands.cc, map_commands.cc; rpc.cc: what they share).
#pragma once

#include <grpcpp/grpcpp.h>

#include <algorithm>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "fusion/clients/cli.h"
#include "fusion/v1/map_service.grpc.pb.h"

namespace fusionctl {

inline constexpr const char* kTool = "fusionctl";

using Stub = fusion::v1::FusionMap::Stub;

struct Context {
  std::string server;
  double timeout_s = 10.0;
  std::shared_ptr<grpc::Channel> channel;
  std::unique_ptr<Stub> stub;
};

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

// rpc.cc
void SetDeadline(grpc::ClientContext* context, double seconds);
// A unary call of fusiond (ctx.stub) that must answer within timeout_s seconds.
template <typename Request, typename Reply>
grpc::Status Call(const Context& ctx,
                  grpc::Status (Stub::*method)(grpc::ClientContext*, const Request&, Reply*),
                  const Request& request, Reply* reply, double timeout_s) {
  grpc::ClientContext context;
  SetDeadline(&context, timeout_s);
  return (ctx.stub.get()->*method)(&context, request, reply);
}
// Reports a failed call (unreachable service or its error); returns kExitFailure.
int Failed(const Context& ctx, const grpc::Status& status);
// A bad command line: "fusionctl: <message> (see fusionctl --help)"; returns kExitUsage.
inline int Usage(const std::string& message) { return fusion::clients::UsageError(kTool, message); }
// args[at..at+2] as a point (metres); false if missing or not numbers.
bool ParsePoint(const std::vector<std::string>& args, std::size_t at, fusion::v1::Point* p);
const char* StateName(fusion::v1::VoxelState s);

// Each command returns the process's exit code.
// status_commands.cc: the service's health, counters and its map as a whole.
int Health(Context& ctx, const Args& args);
int Stats(Context& ctx, const Args& args);
int Sensors(Context& ctx, const Args& args);
int Reset(Context& ctx, const Args& args);
int Save(Context& ctx, const Args& args);
// query_commands.cc: questions about places in the map.
int Points(Context& ctx, const Args& args);
int Box(Context& ctx, const Args& args);
int Ray(Context& ctx, const Args& args);
int Planes(Context& ctx, const Args& args);
int Beam(Context& ctx, const Args& args);
// map_commands.cc: the map's contents, whole or as a stream of changes.
int Snapshot(Context& ctx, const Args& args);
int Render(Context& ctx, const Args& args);
int Watch(Context& ctx, const Args& args);

}  // namespace fusionctl
