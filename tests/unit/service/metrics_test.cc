// fusiond's metrics in process (service/src/metrics.cc): a MapStack whose worker observes the
// histograms, a MapService behind the RPC interceptor, the endpoint on 127.0.0.1:0, scraped
// while clouds are integrated and calls answered (clean under the thread sanitizer too).
#include "fusion/service/metrics.h"

#include <gtest/gtest.h>

#include <atomic>
#include <string>
#include <thread>

#include "../../support/http_get.h"
#include "../../support/prometheus_text.h"
#include "handler_fixture.h"

namespace fusion::service::testing {
namespace {

using fusion::testing::HttpGet;
using fusion::testing::PrometheusText;

class MetricsTest : public HandlerTest {
 protected:
  // HandlerTest::StartService with metrics: histograms into the worker, the interceptor.
  void SetUp() override {
    config_ = DefaultConfig();
    config_.MergeFrom(
        Text<v1::ServiceConfig>("log_level: \"warn\"\n"
                                "sensors { id: \"cam\" preset: \"sr3000\" cols: 22 rows: 18 }\n"
                                "map { resolution_m: 0.05 render_interval_ms: 10 }\n"));
    const fusion::Status listening = metrics_.Listen("127.0.0.1:0");
    ASSERT_TRUE(listening.ok()) << listening.message();
    stack_ = std::make_unique<MapStack>(config_, nullptr);
    stack_->set_worker_histograms(metrics_.worker());
    const fusion::Status started = stack_->Start();
    ASSERT_TRUE(started.ok()) << started.message();
    metrics_.Observe(stack_->state());
    service_ = std::make_unique<MapService>(stack_->state());
    grpc::ServerBuilder builder;
    builder.RegisterService(service_.get());
    std::vector<std::unique_ptr<grpc::experimental::ServerInterceptorFactoryInterface>> creators;
    creators.push_back(metrics_.RpcInterceptorFactory());
    builder.experimental().SetInterceptorCreators(std::move(creators));
    server_ = builder.BuildAndStart();
    ASSERT_NE(server_, nullptr);
    stub_ = v1::FusionMap::NewStub(server_->InProcessChannel(grpc::ChannelArguments()));
  }
  void TearDown() override {
    HandlerTest::TearDown();
    metrics_.Stop();
  }

  PrometheusText Scrape() {
    std::string head;
    const auto parsed = PrometheusText::Parse(HttpGet(metrics_.port(), "/metrics", &head));
    EXPECT_TRUE(parsed.ok()) << parsed.error;
    return parsed;
  }

  Metrics metrics_;
};

// Scrapes race the worker and each other (no gRPC call: what the thread sanitizer checks is
// the collector's reads against the worker's writes, and the histograms).
TEST_F(MetricsTest, ScrapesWhileTheWorkerIntegrates) {
  ASSERT_GT(metrics_.port(), 0);
  std::atomic<bool> done{false};
  std::atomic<int> scrapes{0};
  std::thread scraper([&] {
    while (!done) {
      if (Scrape().ok()) ++scrapes;
      std::this_thread::sleep_for(5ms);
    }
  });
  SeeWall(6);
  done = true;
  scraper.join();
  EXPECT_GT(scrapes.load(), 0);

  const PrometheusText m = Scrape();
  const ServiceState& state = *stack_->state();
  EXPECT_EQ(m.Value(R"(fusiond_clouds_integrated_total{sensor="cam"})"), 6.0);
  EXPECT_EQ(m.Value(R"(fusiond_clouds_received_total{sensor="cam"})"), 6.0);
  EXPECT_EQ(m.Value("fusiond_clouds_in_map"), 6.0);
  EXPECT_EQ(m.Value("fusiond_integration_duration_seconds_count"), 6.0);
  EXPECT_EQ(m.Value("fusiond_dds_to_queryable_seconds_count"), 6.0);
  EXPECT_GE(m.Value("fusiond_render_duration_seconds_count"), 1.0);
  EXPECT_EQ(m.Value("fusiond_renders_total"), static_cast<double>(state.worker->renders()));
  EXPECT_EQ(m.Value("fusiond_map_leaves"),
            static_cast<double>(state.hub->Current()->sizes().leaves));
  EXPECT_GT(m.Value("fusiond_map_leaves"), 0.0);

  // A reset empties the map: clouds_in_map follows, the counters do not go back.
  (void)state.worker->Reset();
  const PrometheusText after = Scrape();
  EXPECT_EQ(after.Value("fusiond_clouds_in_map"), 0.0);
  EXPECT_EQ(after.Value(R"(fusiond_clouds_integrated_total{sensor="cam"})"), 6.0);
}

// Calls through the interceptor, counted by method and code.
TEST_F(MetricsTest, CallsAreCountedByMethodAndCode) {
  for (int i = 0; i < 4; ++i) (void)Stats();
  v1::CastRayResponse ray;
  EXPECT_EQ(CastRay("origin { z: 0 } direction { z: 0 } max_range_m: 1", &ray).error_code(),
            grpc::StatusCode::INVALID_ARGUMENT);
  const PrometheusText m = Scrape();
  const std::string service = R"(service="fusion.v1.FusionMap"})";
  EXPECT_EQ(m.Value(R"(fusiond_rpcs_total{code="OK",method="GetStats",)" + service), 4.0);
  EXPECT_EQ(m.Value(R"(fusiond_rpc_duration_seconds_count{method="GetStats",)" + service), 4.0);
  EXPECT_EQ(m.Value(R"(fusiond_rpcs_total{code="INVALID_ARGUMENT",method="CastRay",)" + service),
            1.0);
  EXPECT_FALSE(m.Has(R"(fusiond_rpcs_total{code="OK",method="CastRay",)" + service));
}

}  // namespace
}  // namespace fusion::service::testing
