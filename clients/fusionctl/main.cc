// fusionctl: command-line client of fusiond.
#include <chrono>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include <grpcpp/grpcpp.h>
#include <grpcpp/health_check_service_interface.h>

#include "fusion/v1/map_service.grpc.pb.h"
#include "grpc/health/v1/health.grpc.pb.h"

namespace {

constexpr const char* kUsage = R"(fusionctl: command-line client of fusiond

Usage: fusionctl [--server HOST:PORT] [--timeout SECONDS] COMMAND
  --server HOST:PORT  fusiond's gRPC address (default 127.0.0.1:50051)
  --timeout SECONDS   deadline of each call (default 5)

Commands:
  health   ask the standard grpc.health.v1 service; exit 0 when SERVING
  stats    print the map version, counters and uptime
)";

std::chrono::system_clock::time_point Deadline(double seconds) {
  return std::chrono::system_clock::now() +
         std::chrono::milliseconds(static_cast<long>(seconds * 1000));
}

int Unreachable(const std::string& server, const grpc::Status& status) {
  std::fprintf(stderr, "fusionctl: %s: %s (is fusiond running there?)\n", server.c_str(),
               status.error_message().c_str());
  return 1;
}

}  // namespace

int main(int argc, char** argv) {
  std::string server = "127.0.0.1:50051";
  double timeout_s = 5.0;
  std::vector<std::string> args;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    if (arg == "--help" || arg == "-h") {
      std::fputs(kUsage, stdout);
      return 0;
    } else if (arg == "--server" && i + 1 < argc) {
      server = argv[++i];
    } else if (arg == "--timeout" && i + 1 < argc) {
      timeout_s = std::atof(argv[++i]);
    } else {
      args.push_back(arg);
    }
  }
  if (args.empty()) {
    std::fputs(kUsage, stderr);
    return 2;
  }
  auto channel = grpc::CreateChannel(server, grpc::InsecureChannelCredentials());
  const std::string& command = args[0];
  if (command == "health") {
    auto stub = grpc::health::v1::Health::NewStub(channel);
    grpc::ClientContext context;
    context.set_deadline(Deadline(timeout_s));
    grpc::health::v1::HealthCheckRequest request;
    grpc::health::v1::HealthCheckResponse reply;
    const auto status = stub->Check(&context, request, &reply);
    if (!status.ok()) return Unreachable(server, status);
    const bool serving = reply.status() == grpc::health::v1::HealthCheckResponse::SERVING;
    std::printf("%s\n", serving ? "SERVING" : "NOT_SERVING");
    return serving ? 0 : 1;
  }
  if (command == "stats") {
    auto stub = fusion::v1::FusionMap::NewStub(channel);
    grpc::ClientContext context;
    context.set_deadline(Deadline(timeout_s));
    fusion::v1::Stats reply;
    const auto status = stub->GetStats(&context, fusion::v1::GetStatsRequest(), &reply);
    if (!status.ok()) return Unreachable(server, status);
    std::printf("map_version %llu\nclouds_received %llu\nclouds_rejected %llu\nuptime_s %.1f\n",
                static_cast<unsigned long long>(reply.map_version()),
                static_cast<unsigned long long>(reply.clouds_received()),
                static_cast<unsigned long long>(reply.clouds_rejected()), reply.uptime_s());
    return 0;
  }
  std::fprintf(stderr, "fusionctl: unknown command '%s' (see --help)\n", command.c_str());
  return 2;
}
