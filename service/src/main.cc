// fusiond: the forward-model occupancy fusion service.
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <string>

#include <spdlog/spdlog.h>

#include "fusion/service/config.h"
#include "fusion/service/server.h"

namespace {

constexpr const char* kUsage = R"(fusiond: forward-model occupancy fusion service

Subscribes to point clouds over DDS, fuses them into an occupancy map and answers gRPC
queries on it.

Usage: fusiond [options]
  --config FILE       configuration (.pbtxt protobuf text format, or .json)
  --listen HOST:PORT  gRPC listen address (default 127.0.0.1:0: the OS picks the port)
  --dds-domain N      DDS domain id (default 0)
  --log-level LEVEL   trace, debug, info, warn, error, critical, off (default info)
  --help              this text

On start it prints "fusiond listening on HOST:PORT". SIGINT or SIGTERM stops it cleanly.
Unless CYCLONEDDS_URI is set, DDS runs with an embedded configuration on 127.0.0.1.
)";

int Fail(const std::string& message) {
  std::fprintf(stderr, "fusiond: %s\n", message.c_str());
  return 2;
}

}  // namespace

int main(int argc, char** argv) {
  auto config = fusion::service::DefaultConfig();
  std::string error;
  // The config file first, so flags override it wherever they stand.
  for (int i = 1; i + 1 < argc; ++i) {
    if (std::string(argv[i]) == "--config" &&
        !fusion::service::LoadConfigFile(argv[i + 1], &config, &error)) {
      return Fail(error);
    }
  }
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    const bool has_value = i + 1 < argc;
    if (arg == "--help" || arg == "-h") {
      std::fputs(kUsage, stdout);
      return 0;
    } else if (arg == "--config" && has_value) {
      ++i;
    } else if (arg == "--listen" && has_value) {
      config.set_listen_address(argv[++i]);
    } else if (arg == "--dds-domain" && has_value) {
      char* end = nullptr;
      const long domain = std::strtol(argv[++i], &end, 10);
      if (*end != '\0' || domain < 0) return Fail("--dds-domain: not a domain id: " + std::string(argv[i]));
      config.set_dds_domain(static_cast<unsigned>(domain));
    } else if (arg == "--log-level" && has_value) {
      config.set_log_level(argv[++i]);
    } else {
      return Fail("unknown or incomplete option '" + arg + "' (see --help)");
    }
  }
  if (!fusion::service::ValidateConfig(config, &error)) return Fail(error);
  spdlog::set_level(spdlog::level::from_str(config.log_level()));

  // Block the stop signals in every thread; main waits for them below.
  sigset_t stop_signals;
  sigemptyset(&stop_signals);
  sigaddset(&stop_signals, SIGINT);
  sigaddset(&stop_signals, SIGTERM);
  pthread_sigmask(SIG_BLOCK, &stop_signals, nullptr);

  fusion::service::FusionServer server(config);
  if (!server.Start(&error)) return Fail(error);
  const std::string host = config.listen_address().substr(0, config.listen_address().rfind(':'));
  std::printf("fusiond listening on %s:%d\n", host.c_str(), server.port());
  std::fflush(stdout);
  spdlog::info("listening on {}:{}, DDS domain {}, topic '{}'", host, server.port(),
               config.dds_domain(), config.dds_topic());

  int signal_number = 0;
  sigwait(&stop_signals, &signal_number);
  spdlog::info("signal {} received, shutting down", signal_number);
  server.Shutdown();
  spdlog::info("stopped");
  return 0;
}
