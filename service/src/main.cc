// fusiond: the forward-model occupancy fusion service.
#include <malloc.h>

#include <spdlog/spdlog.h>

#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <string>

#include "fusion/service/config.h"
#include "fusion/service/logging.h"
#include "fusion/service/server.h"

namespace {

constexpr const char* kUsage = R"(fusiond: forward-model occupancy fusion service

Subscribes to point clouds over DDS, fuses them into an occupancy map and answers gRPC
queries on it.

Usage: fusiond [options]
  --config FILE       configuration (.pbtxt protobuf text format, or .json)
  --listen HOST:PORT  gRPC listen address (default 127.0.0.1:0: the OS picks the port)
  --dds-domain N      DDS domain id (default 0)
  --dds-topic NAME    DDS topic of the point clouds (default fusion/points)
  --log-level LEVEL   trace, debug, info, warn, error, critical, off (default info)
  --log-format FMT    text (default) or json (one object a line)
  --sensor ID=PRESET  accept clouds of sensor ID, modelled with PRESET (sr3000, stoc);
                      repeatable, added to the configuration file's sensors
  --resolution M      map voxel size in metres (default 0.05)
  --render-interval-ms MS  render cadence (default 10)
  --snapshot FILE     snapshot file (.ot): loaded at start, written periodically and on exit
  --snapshot-interval S    periodic snapshot interval in seconds, 0 = only on exit (default 30)
  --metrics-listen HOST:PORT  Prometheus /metrics over HTTP (default off; e.g.
                      127.0.0.1:9464, port 0: the OS picks; docs/operations.md)
  --tls-cert FILE     TLS: the server's certificate chain (PEM); with --tls-key
  --tls-key FILE      TLS: the server's private key (PEM)
  --tls-client-ca FILE  mutual TLS: clients need a certificate signed by this CA
  --tokens-file FILE  bearer tokens, lines "<read|admin> <token>"; needs TLS
                      (docs/security.md; scripts/make_certs.sh makes all four)
  --help              this text

A bad configuration is refused with a message naming the field; see docs/service.md.

On start it prints "fusiond listening on HOST:PORT" (and before it "fusiond metrics on
HOST:PORT" when metrics are on: docs/operations.md). SIGINT or SIGTERM stops it cleanly.
Unless CYCLONEDDS_URI is set, DDS runs with an embedded configuration on 127.0.0.1.
)";

int Fail(const std::string& message) {
  std::fprintf(stderr, "fusiond: %s\n", message.c_str());
  return 2;
}

bool ParseDouble(const char* text, double* value) {
  char* end = nullptr;
  *value = std::strtod(text, &end);
  return end != text && *end == '\0';
}

bool ParseUnsigned(const char* text, unsigned long* value) {
  char* end = nullptr;
  if (*text == '-') return false;
  *value = std::strtoul(text, &end, 10);
  return end != text && *end == '\0';
}

}  // namespace

// The flags over the configuration; -1 to go on, else the exit code (--help: 0, bad: 2).
int ApplyFlags(int argc, char** argv, fusion::v1::ServiceConfig* config_out) {
  auto& config = *config_out;
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
      unsigned long domain = 0;
      if (!ParseUnsigned(argv[++i], &domain) || domain > 0xffffffffUL) {
        return Fail("--dds-domain: not a domain id: " + std::string(argv[i]));
      }
      config.set_dds_domain(static_cast<unsigned>(domain));
    } else if (arg == "--dds-topic" && has_value) {
      config.set_dds_topic(argv[++i]);
    } else if (arg == "--log-level" && has_value) {
      config.set_log_level(argv[++i]);
    } else if (arg == "--log-format" && has_value) {
      config.set_log_format(argv[++i]);
    } else if (arg == "--sensor" && has_value) {
      const fusion::Status parsed = fusion::service::ParseSensorFlag(argv[++i], config.add_sensors());
      if (!parsed.ok()) return Fail(parsed.message());
    } else if (arg == "--resolution" && has_value) {
      double resolution = 0.0;
      if (!ParseDouble(argv[++i], &resolution)) return Fail("--resolution: not a number");
      config.mutable_map()->set_resolution_m(resolution);
    } else if (arg == "--render-interval-ms" && has_value) {
      unsigned long ms = 0;
      if (!ParseUnsigned(argv[++i], &ms) || ms > 600000) {
        return Fail("--render-interval-ms: not a number of milliseconds");
      }
      config.mutable_map()->set_render_interval_ms(static_cast<unsigned>(ms));
    } else if (arg == "--metrics-listen" && has_value) {
      config.mutable_metrics()->set_listen_address(argv[++i]);
    } else if (arg == "--tls-cert" && has_value) {
      config.mutable_security()->set_tls_cert_file(argv[++i]);
    } else if (arg == "--tls-key" && has_value) {
      config.mutable_security()->set_tls_key_file(argv[++i]);
    } else if (arg == "--tls-client-ca" && has_value) {
      config.mutable_security()->set_tls_client_ca_file(argv[++i]);
    } else if (arg == "--tokens-file" && has_value) {
      config.mutable_security()->set_tokens_file(argv[++i]);
    } else if (arg == "--snapshot" && has_value) {
      config.mutable_persistence()->set_path(argv[++i]);
    } else if (arg == "--snapshot-interval" && has_value) {
      unsigned long s = 0;
      if (!ParseUnsigned(argv[++i], &s) || s > 86400) {
        return Fail("--snapshot-interval: not a number of seconds");
      }
      config.mutable_persistence()->set_interval_s(static_cast<unsigned>(s));
    } else {
      return Fail("unknown or incomplete option '" + arg + "' (see --help)");
    }
  }
  return -1;
}

int main(int argc, char** argv) {
  // Clouds are megabytes: allocations of 1 MiB and more are mapped and unmapped on their own,
  // so memory freed after a burst returns to the system (glibc would otherwise raise this
  // threshold after the first free and keep freed clouds in its arenas).
  mallopt(M_MMAP_THRESHOLD, 1 << 20);
  auto config = fusion::service::DefaultConfig();
  // The config file first, so flags override it wherever they stand.
  for (int i = 1; i + 1 < argc; ++i) {
    if (std::string(argv[i]) != "--config") continue;
    const fusion::Status loaded = fusion::service::LoadConfigFile(argv[i + 1], &config);
    if (!loaded.ok()) return Fail(loaded.message());
  }
  if (const int exit_code = ApplyFlags(argc, argv, &config); exit_code >= 0) return exit_code;
  if (const fusion::Status valid = fusion::service::ValidateConfig(config); !valid.ok()) {
    return Fail(valid.message());
  }
  // Block the stop signals in every thread, before the first one (the log's) starts: a stop
  // signal must reach main's wait below, not kill the process on a thread that never blocked it.
  sigset_t stop_signals;
  sigemptyset(&stop_signals);
  sigaddset(&stop_signals, SIGINT);
  sigaddset(&stop_signals, SIGTERM);
  pthread_sigmask(SIG_BLOCK, &stop_signals, nullptr);

  // Logs go to stderr: stdout carries only the "listening on" line a parent may read.
  fusion::service::SetUpLogging(config.log_format(), config.log_level());

  fusion::service::FusionServer server(config);
  if (const fusion::Status started = server.Start(); !started.ok()) {
    // Not Fail: fd 2 is the log's capture pipe by now (logging.cc), and the process would exit
    // before its reader passes the message on. The log goes to the real stderr at once.
    spdlog::critical("{}", started.message());
    return 2;
  }
  const std::string host = config.listen_address().substr(0, config.listen_address().rfind(':'));
  // Before the listening line: a parent that read that line finds this one too.
  const std::string& metrics_address = config.metrics().listen_address();
  if (server.metrics_port() > 0) {
    const std::string metrics_host = metrics_address.substr(0, metrics_address.rfind(':'));
    std::printf("fusiond metrics on %s:%d\n", metrics_host.c_str(), server.metrics_port());
    spdlog::info("metrics on http://{}:{}/metrics", metrics_host, server.metrics_port());
  }
  std::printf("fusiond listening on %s:%d\n", host.c_str(), server.port());
  std::fflush(stdout);
  spdlog::info("listening on {}:{}, DDS domain {}, topic '{}'", host, server.port(),
               config.dds_domain(), config.dds_topic());

  int signal_number = 0;
  sigwait(&stop_signals, &signal_number);
  spdlog::info("signal {} received, shutting down", signal_number);
  if (const fusion::Status stopped = server.Shutdown(); !stopped.ok()) {
    spdlog::error("stopped without its final snapshot: {}", stopped.message());
    return 1;
  }
  spdlog::info("stopped");
  return 0;
}
