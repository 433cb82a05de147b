// fusiond's metrics in process (service/src/metrics.cc): a MapStack whose worker observes the
// histograms, a MapService behind the RPC interceptor, the endpoint on 127.0.0.1:0, scraped
// while clouds are integrated and calls answered (the thread sanitizer build runs this too).
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
    std::string error;
    ASSERT_TRUE(metrics_.Listen("127.0.0.1:0", &error)) << error;
    stack_ = std::make_unique<MapStack>(config_, nullptr);
    stack_->set_worker_histograms(metrics_.worker());
    ASSERT_TRUE(stack_->Start(&error)) << error;
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

TEST_F(MetricsTest, ScrapesWhileTheWorkerIntegratesAndCallsAreAnswered) {
  ASSERT_GT(metrics_.port(), 0);
  std::atomic<bool> done{false};
  std::atomic<int> scrapes{0};
  std::thread scraper([&] {  // scrapes race the worker, the calls and each other
    while (!done) {
      if (Scrape().ok()) ++scrapes;
      std::this_thread::sleep_for(5ms);
    }
  });
  SeeWall(6);
  for (int i = 0; i < 4; ++i) (void)Stats();
  v1::CastRayResponse ray;
  EXPECT_EQ(CastRay("origin { z: 0 } direction { z: 0 } max_range_m: 1", &ray).error_code(),
            grpc::StatusCode::INVALID_ARGUMENT);
  done = true;
  scraper.join();
  EXPECT_GT(scrapes.load(), 0);

  const PrometheusText m = Scrape();
  const v1::Stats stats = Stats();
  EXPECT_EQ(m.Value(R"(fusiond_clouds_integrated_total{sensor="cam"})"), 6.0);
  EXPECT_EQ(m.Value(R"(fusiond_clouds_integrated_total{sensor="cam"})"),
            static_cast<double>(stats.clouds_integrated()));
  EXPECT_EQ(m.Value("fusiond_clouds_in_map"), 6.0);
  EXPECT_EQ(m.Value("fusiond_integration_duration_seconds_count"), 6.0);
  EXPECT_EQ(m.Value("fusiond_dds_to_queryable_seconds_count"), 6.0);
  EXPECT_GE(m.Value("fusiond_render_duration_seconds_count"), 1.0);
  EXPECT_EQ(m.Value("fusiond_map_leaves"), static_cast<double>(stats.map_leaves()));
  EXPECT_EQ(
      m.Value(R"(fusiond_rpcs_total{code="OK",method="GetStats",service="fusion.v1.FusionMap"})"),
      4.0);
  EXPECT_EQ(m.Value(R"(fusiond_rpcs_total{code="INVALID_ARGUMENT",method="CastRay",)"
                    R"(service="fusion.v1.FusionMap"})"),
            1.0);

  // ResetMap empties the map: clouds_in_map follows, the counters do not go back.
  v1::ResetMapResponse reset;
  ASSERT_TRUE(Unary(&v1::FusionMap::Stub::ResetMap, v1::ResetMapRequest(), &reset).ok());
  const PrometheusText after = Scrape();
  EXPECT_EQ(after.Value("fusiond_clouds_in_map"), 0.0);
  EXPECT_EQ(after.Value(R"(fusiond_clouds_integrated_total{sensor="cam"})"), 6.0);
}

}  // namespace
}  // namespace fusion::service::testing
