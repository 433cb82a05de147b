// Prometheus metrics over HTTP (docs/operations.md lists every one). Off unless
// metrics.listen_address is set: then nothing is measured and no thread is started.
//
// One place for each count: the counters and gauges are read at scrape time from the same
// atomics GetStats reads (ServiceState); only what has no counter elsewhere is observed as it
// happens: the worker's step durations and DDS-to-queryable latency (WorkerHistograms, null when
// off) and every RPC's status code and duration (a gRPC server interceptor).
#pragma once

#include <grpcpp/support/server_interceptor.h>

#include <memory>
#include <string>

#include "fusion/core/status.h"

namespace prometheus {
class Histogram;
}  // namespace prometheus

namespace fusion::service {

struct ServiceState;
class Ros2Output;

// What the fusion worker observes; each may be null (metrics off: not even a clock is read).
struct WorkerHistograms {
  prometheus::Histogram* integration_seconds = nullptr;       // one cloud into its beam grid
  prometheus::Histogram* render_seconds = nullptr;            // one beam grid into the map
  prometheus::Histogram* dds_to_queryable_seconds = nullptr;  // DDS sample to published map
};

class Metrics {
 public:
  // Registers the metrics; nothing listens until Listen.
  Metrics();
  ~Metrics();
  Metrics(const Metrics&) = delete;
  Metrics& operator=(const Metrics&) = delete;

  [[nodiscard]] const WorkerHistograms& worker() const;
  // Counts and times every RPC of a server built with it (by service, method and status code).
  [[nodiscard]] std::unique_ptr<grpc::experimental::ServerInterceptorFactoryInterface>
  RpcInterceptorFactory();
  // Serves /metrics on `address` ("IPv4:port", "[IPv6]:port"; port 0: the OS chooses); an
  // error when it cannot listen.
  [[nodiscard]] Status Listen(const std::string& address);
  // From now on each scrape also reads the counters and gauges of `state` (once it is set up:
  // its queues, worker, hub and persister). `state` must outlive Stop.
  void Observe(const ServiceState* state);
  // From now on each scrape also reads the ROS 2 output's counts per topic (publications,
  // bytes, failures, matched subscribers). `output` must outlive Stop.
  void ObserveRos2Output(const Ros2Output* output);
  // The port Listen bound (0 before).
  [[nodiscard]] int port() const;
  // Stops the HTTP server (waits for a scrape in progress); no scrape reads the state after.
  void Stop();

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace fusion::service
