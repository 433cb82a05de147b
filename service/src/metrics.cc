#include "fusion/service/metrics.h"

#include <prometheus/collectable.h>
#include <prometheus/counter.h>
#include <prometheus/exposer.h>
#include <prometheus/family.h>
#include <prometheus/histogram.h>
#include <prometheus/registry.h>

#include <array>
#include <atomic>
#include <chrono>
#include <exception>
#include <mutex>

#include "fusion/service/map_service.h"
#include "fusion/service/ros2_output.h"
#include "fusion/wire/status_names.h"

namespace fusion::service {
namespace {

using prometheus::ClientMetric;
using prometheus::MetricFamily;
using prometheus::MetricType;
using Clock = std::chrono::steady_clock;

// Rejections not attributable to a configured sensor (an unknown or empty sensor id).
constexpr const char* kUnconfiguredSensor = "unconfigured";

// Bucket bounds in seconds, from `first` growing by `factor`.
prometheus::Histogram::BucketBoundaries Exponential(double first, double factor, int count) {
  prometheus::Histogram::BucketBoundaries bounds;
  for (double bound = first; count-- > 0; bound *= factor) bounds.push_back(bound);
  return bounds;
}

// A family of the scrape-time metrics, one sample added per call of Add.
struct FamilyBuilder {
  MetricFamily family;
  FamilyBuilder(const char* name, const char* help, MetricType type)
      : family{name, help, type, {}} {}
  void Add(double value, std::vector<ClientMetric::Label> labels = {}) {
    ClientMetric metric;
    metric.label = std::move(labels);
    if (family.type == MetricType::Counter) {
      metric.counter.value = value;
    } else {
      metric.gauge.value = value;
    }
    family.metric.push_back(std::move(metric));
  }
};

// The counters and gauges of GetStats, read at scrape time (no second count of anything).
class StateCollector final : public prometheus::Collectable {
 public:
  explicit StateCollector(const ServiceState* state) : state_(state) {}

  std::vector<MetricFamily> Collect() const override {
    std::vector<MetricFamily> out;
    CollectClouds(&out);
    CollectMap(&out);
    return out;
  }

 private:
  void CollectClouds(std::vector<MetricFamily>* out) const {
    const auto counter = MetricType::Counter;
    FamilyBuilder received("fusiond_clouds_received_total",
                           "DDS samples received, valid or not, by sensor id", counter);
    FamilyBuilder integrated("fusiond_clouds_integrated_total",
                             "Clouds integrated into their sensor's beam grid", counter);
    FamilyBuilder dropped("fusiond_clouds_dropped_total",
                          "Valid clouds replaced by a newer one before integration", counter);
    FamilyBuilder merged("fusiond_clouds_merged_total",
                         "Clouds merged into an open period while the renderer was behind",
                         counter);
    FamilyBuilder changes("fusiond_changes_detected_total",
                          "Beams restarted because their readings said the world changed",
                          counter);
    FamilyBuilder rejected("fusiond_clouds_rejected_total",
                           "Samples rejected before integration, by sensor id and reason", counter);
    FamilyBuilder queue("fusiond_ingest_queue_clouds",
                        "Clouds waiting for the fusion worker, by sensor", MetricType::Gauge);
    FamilyBuilder grid_bytes("fusiond_beam_grid_memory_bytes", "Memory of a sensor's beam grids",
                             MetricType::Gauge);
    const IngestQueues& queues = *state_->queues;
    std::array<std::uint64_t, kRejectReasonCount> by_sensors{};
    std::uint64_t rejected_by_sensors = 0;
    for (const auto& id : queues.SensorIds()) {
      const SensorCountersAtomic& c = *queues.counters(id);
      const std::uint64_t sensor_rejected = c.rejected.Total();
      rejected_by_sensors += sensor_rejected;
      received.Add(static_cast<double>(c.received.load() + sensor_rejected), {{"sensor", id}});
      integrated.Add(static_cast<double>(c.integrated.load()), {{"sensor", id}});
      dropped.Add(static_cast<double>(c.dropped.load()), {{"sensor", id}});
      merged.Add(static_cast<double>(c.merged.load()), {{"sensor", id}});
      changes.Add(static_cast<double>(c.changes_detected.load()), {{"sensor", id}});
      queue.Add(static_cast<double>(queues.Pending(id)), {{"sensor", id}});
      grid_bytes.Add(static_cast<double>(c.memory_bytes.load()), {{"sensor", id}});
      for (std::size_t i = 0; i < kRejectReasonCount; ++i) {
        const std::uint64_t n = c.rejected.by_reason[i].load();
        by_sensors[i] += n;
        rejected.Add(static_cast<double>(n),
                     {{"reason", RejectReasonName(RejectReason(i))}, {"sensor", id}});
      }
    }
    // The rest of all_rejected: samples of no configured sensor. Read after the sensors' (they
    // are counted after it), so the difference does not go below zero.
    const RejectCounters& all = queues.all_rejected();
    const auto Rest = [](std::uint64_t total, std::uint64_t part) {
      return static_cast<double>(total > part ? total - part : 0);
    };
    received.Add(Rest(all.Total(), rejected_by_sensors), {{"sensor", kUnconfiguredSensor}});
    for (std::size_t i = 0; i < kRejectReasonCount; ++i) {
      rejected.Add(
          Rest(all.by_reason[i].load(), by_sensors[i]),
          {{"reason", RejectReasonName(RejectReason(i))}, {"sensor", kUnconfiguredSensor}});
    }
    FamilyBuilder queue_bytes("fusiond_ingest_queue_bytes",
                              "Bytes of the clouds waiting for the fusion worker",
                              MetricType::Gauge);
    queue_bytes.Add(static_cast<double>(queues.queued_bytes()));
    for (FamilyBuilder* f : {&received, &integrated, &dropped, &merged, &changes, &rejected,
                             &queue, &queue_bytes, &grid_bytes}) {
      out->push_back(std::move(f->family));
    }
  }

  void CollectMap(std::vector<MetricFamily>* out) const {
    const auto gauge = MetricType::Gauge;
    const auto snapshot = state_->hub->Current();
    FamilyBuilder in_map("fusiond_clouds_in_map",
                         "Clouds whose evidence the map that queries see holds", gauge);
    in_map.Add(static_cast<double>(state_->worker->in_map()));
    FamilyBuilder renders("fusiond_renders_total", "Beam-grid renders into the map",
                          MetricType::Counter);
    renders.Add(static_cast<double>(state_->worker->renders()));
    FamilyBuilder version("fusiond_map_version", "Version of the map that queries see", gauge);
    version.Add(static_cast<double>(snapshot->version));
    FamilyBuilder leaves("fusiond_map_leaves", "Leaf nodes of the published map", gauge);
    leaves.Add(static_cast<double>(snapshot->sizes().leaves));
    FamilyBuilder bytes("fusiond_map_memory_bytes", "Memory of the published map's octree", gauge);
    bytes.Add(static_cast<double>(snapshot->sizes().memory_bytes));
    FamilyBuilder written("fusiond_snapshots_written_total",
                          "Snapshot files written (periodic, SaveMap, final)", MetricType::Counter);
    written.Add(static_cast<double>(state_->persister->saves()));
    FamilyBuilder failed("fusiond_snapshots_failed_total", "Snapshot writes that failed",
                         MetricType::Counter);
    failed.Add(static_cast<double>(state_->persister->failures()));
    FamilyBuilder failing("fusiond_persistence_failing",
                          "1 while snapshot writes fail (health: fusion.v1.Persistence "
                          "NOT_SERVING), else 0",
                          gauge);
    failing.Add(state_->persister->failing() ? 1.0 : 0.0);
    FamilyBuilder streams("fusiond_update_stream_subscribers", "StreamUpdates subscriptions open",
                          gauge);
    streams.Add(static_cast<double>(state_->update_streams.load()));
    FamilyBuilder heavy("fusiond_heavy_queries_running",
                        "Expensive calls (FindPlanes, QueryBox, GetSnapshot) running", gauge);
    heavy.Add(static_cast<double>(state_->heavy_queries.load()));
    FamilyBuilder uptime("fusiond_uptime_seconds", "Time since fusiond started", gauge);
    uptime.Add(std::chrono::duration<double>(Clock::now() - state_->start).count());
    for (FamilyBuilder* f : {&in_map, &renders, &version, &leaves, &bytes, &written, &failed,
                             &failing, &streams, &heavy, &uptime}) {
      out->push_back(std::move(f->family));
    }
  }

  const ServiceState* state_;
};

// The ROS 2 output's counts per topic, read at scrape time.
class Ros2OutputCollector final : public prometheus::Collectable {
 public:
  explicit Ros2OutputCollector(const Ros2Output* output) : output_(output) {}

  std::vector<MetricFamily> Collect() const override {
    const auto counter = MetricType::Counter;
    FamilyBuilder publications("fusiond_ros2_publications_total",
                               "Map versions the ROS 2 output wrote, by DDS topic", counter);
    FamilyBuilder bytes("fusiond_ros2_published_bytes_total",
                        "Bytes of the data the ROS 2 output wrote, by DDS topic", counter);
    FamilyBuilder failures("fusiond_ros2_publication_failures_total",
                           "Map versions the ROS 2 output could not write, by DDS topic", counter);
    FamilyBuilder subscribers("fusiond_ros2_matched_subscribers",
                              "DDS readers matched with the ROS 2 output's writer, by DDS topic",
                              MetricType::Gauge);
    for (const Ros2TopicStats& t : output_->TopicStats()) {
      publications.Add(static_cast<double>(t.publications), {{"topic", t.topic}});
      bytes.Add(static_cast<double>(t.bytes), {{"topic", t.topic}});
      failures.Add(static_cast<double>(t.failures), {{"topic", t.topic}});
      subscribers.Add(static_cast<double>(t.matched_subscribers), {{"topic", t.topic}});
    }
    std::vector<MetricFamily> out;
    for (FamilyBuilder* f : {&publications, &bytes, &failures, &subscribers}) {
      out.push_back(std::move(f->family));
    }
    return out;
  }

 private:
  const Ros2Output* output_;
};

// The RPC metrics, shared by every call's interceptor.
struct RpcMetrics {
  prometheus::Family<prometheus::Counter>* calls = nullptr;
  prometheus::Family<prometheus::Histogram>* seconds = nullptr;
};

// Counts and times one call when its status is sent.
class RpcInterceptor final : public grpc::experimental::Interceptor {
 public:
  RpcInterceptor(grpc::experimental::ServerRpcInfo* info, const RpcMetrics* metrics)
      : metrics_(metrics), start_(Clock::now()) {
    const std::string full = info->method() != nullptr ? info->method() : "";  // "/pkg.Svc/M"
    const auto slash = full.rfind('/');
    service_ = slash == std::string::npos || slash == 0 ? "" : full.substr(1, slash - 1);
    method_ = slash == std::string::npos ? full : full.substr(slash + 1);
  }

  void Intercept(grpc::experimental::InterceptorBatchMethods* methods) override {
    using grpc::experimental::InterceptionHookPoints;
    if (methods->QueryInterceptionHookPoint(InterceptionHookPoints::PRE_SEND_STATUS)) {
      const double seconds = std::chrono::duration<double>(Clock::now() - start_).count();
      const char* code =
          fusion::wire::StatusCodeName(static_cast<int>(methods->GetSendStatus().error_code()));
      metrics_->calls->Add({{"service", service_}, {"method", method_}, {"code", code}})
          .Increment();
      metrics_->seconds
          ->Add({{"service", service_}, {"method", method_}}, Exponential(0.0005, 4, 10))
          .Observe(seconds);
    }
    methods->Proceed();
  }

 private:
  const RpcMetrics* metrics_;
  Clock::time_point start_;
  std::string service_, method_;
};

class RpcInterceptorFactory final : public grpc::experimental::ServerInterceptorFactoryInterface {
 public:
  explicit RpcInterceptorFactory(const RpcMetrics* metrics) : metrics_(metrics) {}
  grpc::experimental::Interceptor* CreateServerInterceptor(
      grpc::experimental::ServerRpcInfo* info) override {
    return new RpcInterceptor(info, metrics_);
  }

 private:
  const RpcMetrics* metrics_;
};

}  // namespace

struct Metrics::Impl {
  std::shared_ptr<prometheus::Registry> registry = std::make_shared<prometheus::Registry>();
  WorkerHistograms worker;
  RpcMetrics rpc;
  std::shared_ptr<StateCollector> collector;
  std::shared_ptr<Ros2OutputCollector> ros2_collector;
  std::mutex mutex;  // guards exposer
  std::unique_ptr<prometheus::Exposer> exposer;
  std::atomic<int> port{0};
};

Metrics::Metrics() : impl_(std::make_unique<Impl>()) {
  auto& registry = *impl_->registry;
  const auto Histogram = [&](const char* name, const char* help) {
    return &prometheus::BuildHistogram().Name(name).Help(help).Register(registry);
  };
  impl_->worker.integration_seconds =
      &Histogram("fusiond_integration_duration_seconds",
                 "Time to integrate one cloud into its sensor's beam grid")
           ->Add({}, Exponential(0.0005, 2, 14));
  impl_->worker.render_seconds = &Histogram("fusiond_render_duration_seconds",
                                            "Time to render one sensor's beam grid into the map")
                                      ->Add({}, Exponential(0.001, 2, 15));
  impl_->worker.dds_to_queryable_seconds =
      &Histogram("fusiond_dds_to_queryable_seconds",
                 "From a cloud's arrival over DDS to the first published map that holds it")
           ->Add({}, Exponential(0.005, 2, 14));
  impl_->rpc.calls = &prometheus::BuildCounter()
                          .Name("fusiond_rpcs_total")
                          .Help("gRPC calls finished, by service, method and status code")
                          .Register(registry);
  impl_->rpc.seconds = Histogram("fusiond_rpc_duration_seconds",
                                 "gRPC call duration (until its status is sent), by method");
}

Metrics::~Metrics() { Stop(); }

const WorkerHistograms& Metrics::worker() const { return impl_->worker; }

std::unique_ptr<grpc::experimental::ServerInterceptorFactoryInterface>
Metrics::RpcInterceptorFactory() {
  return std::make_unique<service::RpcInterceptorFactory>(&impl_->rpc);
}

Status Metrics::Listen(const std::string& address) {
  std::lock_guard<std::mutex> lock(impl_->mutex);
  try {
    auto exposer = std::make_unique<prometheus::Exposer>(address, 2);
    exposer->RegisterCollectable(impl_->registry);
    const auto ports = exposer->GetListeningPorts();
    if (ports.empty()) return Status::Error("cannot listen on '" + address + "'");
    impl_->port = ports.front();
    impl_->exposer = std::move(exposer);
  } catch (const std::exception& e) {
    return Status::Error("cannot listen on '" + address + "': " + e.what());
  }
  return Status::Ok();
}

void Metrics::Observe(const ServiceState* state) {
  std::lock_guard<std::mutex> lock(impl_->mutex);
  impl_->collector = std::make_shared<StateCollector>(state);
  if (impl_->exposer) impl_->exposer->RegisterCollectable(impl_->collector);
}

void Metrics::ObserveRos2Output(const Ros2Output* output) {
  std::lock_guard<std::mutex> lock(impl_->mutex);
  impl_->ros2_collector = std::make_shared<Ros2OutputCollector>(output);
  if (impl_->exposer) impl_->exposer->RegisterCollectable(impl_->ros2_collector);
}

int Metrics::port() const { return impl_->port; }

void Metrics::Stop() {
  std::lock_guard<std::mutex> lock(impl_->mutex);
  impl_->exposer.reset();  // joins civetweb's threads
}

}  // namespace fusion::service
