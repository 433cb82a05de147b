// fusionctl's pieces: the call context, a command's arguments and the commands, grouped by file
// (status_commands.cc, query_commands.cc, map_commands.cc; command_line.cc: the options and
// each command's usage; rpc.cc: the channel and what the calls share; output.cc: --json).
#pragma once

#include <grpcpp/grpcpp.h>

#include <algorithm>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "connection.h"
#include "fusion/clients/cli.h"
#include "fusion/v1/map_service.grpc.pb.h"
#include "fusion/wire/status_names.h"

namespace google::protobuf {
class Message;
}

namespace fusionctl {

inline constexpr const char* kTool = "fusionctl";

using Stub = fusion::v1::FusionMap::Stub;

struct Context {
  ConnectionOptions connection;
  // The deadline of each call: the command's default unless --timeout; 0 = none (watch).
  double timeout_s = 10.0;
  bool json = false;         // --json: one JSON document per result on stdout
  std::string bearer_token;  // from connection.token_file_path; empty: none
  std::shared_ptr<grpc::Channel> channel;
  std::unique_ptr<Stub> stub;
};

// Positional arguments, --name value options and flags of one command (command_line.cc has
// checked them against the command's own list).
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

// The whole tool (main.cc calls it; the tests too): returns the exit code.
int Run(int argc, char** argv);

// rpc.cc
// The deadline (none for seconds <= 0) and the bearer token of one call.
void PrepareCall(const Context& ctx, grpc::ClientContext* context, double timeout_s);
// A unary call of fusiond (ctx.stub) that must answer within ctx.timeout_s.
template <typename Request, typename Reply>
grpc::Status Call(const Context& ctx,
                  grpc::Status (Stub::*method)(grpc::ClientContext*, const Request&, Reply*),
                  const Request& request, Reply* reply) {
  grpc::ClientContext context;
  PrepareCall(ctx, &context, ctx.timeout_s);
  return (ctx.stub.get()->*method)(&context, request, reply);
}
// "OK", "INVALID_ARGUMENT", ... (grpc::StatusCode's names; the wire's one table).
using fusion::wire::StatusCodeName;
// Reports a failed call: unreachable service, deadline or the service's error with its status
// name and detail; returns kExitFailure.
int Failed(const Context& ctx, const grpc::Status& status);
// A bad command line: "fusionctl: <message> (see fusionctl --help)"; returns kExitUsage.
inline int Usage(const std::string& message) { return fusion::clients::UsageError(kTool, message); }
// args[at..at+2] as a point (metres); false if missing or not numbers.
bool ParsePoint(const std::vector<std::string>& args, std::size_t at, fusion::v1::Point* p);
// A whole-string unsigned integer option; `fallback` when absent. False: not a number.
bool OptionUint(const Args& args, const std::string& name, unsigned long long fallback,
                unsigned long long* value);
const char* StateName(fusion::v1::VoxelState s);

// output.cc
// One line of JSON on stdout: the proto3 JSON mapping of `message` with the .proto field names
// and fields at their default values included (docs/clients.md).
void PrintJson(const google::protobuf::Message& message);
// A document of fusionctl's own (snapshot, render: no reply message), one line of JSON.
void PrintJsonFields(const std::map<std::string, std::string>& strings,
                     const std::map<std::string, double>& numbers);

// Each command returns the process's exit code.
// status_commands.cc: the service's health, counters and its map as a whole.
int Health(Context& ctx, const Args& args);
int Stats(Context& ctx, const Args& args);
int Sensors(Context& ctx, const Args& args);
int Reset(Context& ctx, const Args& args);
int ClearBox(Context& ctx, const Args& args);
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
