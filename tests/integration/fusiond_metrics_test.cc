// fusiond's Prometheus endpoint (docs/operations.md): a real fusiond with metrics on
// 127.0.0.1:0, scraped over HTTP on loopback; every line of the text format is checked
// (tests/support/prometheus_text.h) and `promtool check metrics` must accept it; the counters
// move when clouds arrive and when RPCs are made, and agree with GetStats.
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include <chrono>
#include <csignal>
#include <fstream>
#include <iterator>
#include <regex>
#include <string>
#include <thread>

#include "../support/fusiond_fixture.h"
#include "../support/http_get.h"
#include "../support/prometheus_text.h"

namespace {

using namespace fusion::testing;  // NOLINT: the fixture and its helpers
using namespace std::chrono_literals;
namespace v1 = fusion::v1;

class FusiondMetricsTest : public FusiondServiceTest {
 protected:
  // Starts fusiond with metrics on 127.0.0.1:0 and reads the port it bound.
  std::unique_ptr<Subprocess> StartWithMetrics() {
    std::ofstream(config_, std::ios::app) << "metrics { listen_address: \"127.0.0.1:0\" }\n";
    auto fusiond = Start();
    if (!fusiond) return nullptr;
    const auto port = fusiond->WaitForOutput(R"(fusiond metrics on 127\.0\.0\.1:(\d+))", 5s);
    EXPECT_TRUE(port) << "no metrics line in: " << fusiond->output();
    if (!port) return nullptr;
    metrics_port_ = std::stoi(*port);
    return fusiond;
  }

  // One scrape, parsed strictly; a format error fails the test.
  PrometheusText Scrape() {
    std::string head;
    body_ = HttpGet(metrics_port_, "/metrics", &head);
    EXPECT_EQ(head.rfind("HTTP/1.1 200", 0), 0u) << head;
    // The text format (prometheus-cpp 1.0.1 names no version: Prometheus reads it as 0.0.4).
    EXPECT_NE(head.find("Content-Type: text/plain"), std::string::npos) << head;
    EXPECT_NE((head + "\r\n").find("Content-Length: " + std::to_string(body_.size()) + "\r\n"),
              std::string::npos)
        << head;
    auto parsed = PrometheusText::Parse(body_);
    EXPECT_TRUE(parsed.ok()) << parsed.error;
    return parsed;
  }

  // Scrapes until `done` holds (the worker publishes asynchronously), at most 15 s.
  template <typename Done>
  PrometheusText ScrapeUntil(Done done) {
    const auto end = std::chrono::steady_clock::now() + 15s;
    PrometheusText metrics = Scrape();
    while (!done(metrics) && std::chrono::steady_clock::now() < end) {
      std::this_thread::sleep_for(100ms);
      metrics = Scrape();
    }
    EXPECT_TRUE(done(metrics)) << body_;
    return metrics;
  }

  int metrics_port_ = 0;
  std::string body_;  // the last scrape
};

const std::string kReceived = R"(fusiond_clouds_received_total{sensor="sr"})";
const std::string kIntegrated = R"(fusiond_clouds_integrated_total{sensor="sr"})";
const std::string kInMap = "fusiond_clouds_in_map";
const std::string kUnknownSensor =
    R"(fusiond_clouds_rejected_total{reason="unknown_sensor",sensor="unconfigured"})";

std::string RpcSeries(const std::string& method, const std::string& code) {
  return R"(fusiond_rpcs_total{code=")" + code + R"(",method=")" + method +
         R"(",service="fusion.v1.FusionMap"})";
}

// Every family is typed and documented; fusiond's counters and only they end in _total.
void ExpectTypedDocumentedAndNamed(const PrometheusText& metrics) {
  for (const auto& [name, type] : metrics.types) {
    EXPECT_FALSE(metrics.help.at(name).empty()) << name;
    if (name.rfind("fusiond_", 0) != 0) continue;
    const bool total = name.size() > 6 && name.compare(name.size() - 6, 6, "_total") == 0;
    EXPECT_EQ(type == "counter", total) << name << " is a " << type;
  }
}

// `promtool check metrics` (format and naming lint) accepts `body`; skipped without promtool.
void ExpectPromtoolAccepts(const std::string& body, const std::string& file) {
  Subprocess which({"/bin/sh", "-c", "command -v promtool || echo none"});
  const auto promtool = which.WaitForOutput(R"((\S+)\n)", 5s);
  (void)which.Wait(5s);
  if (!promtool || *promtool == "none") {
    GTEST_SKIP() << "promtool not installed (Debian package 'prometheus'): format checked by "
                    "the test's own parser only";
  }
  std::ofstream(file) << body;
  Subprocess check(
      {"/bin/sh", "-c", *promtool + " check metrics < '" + file + "' 2>&1; echo rc=$?"});
  const auto rc = check.WaitForOutput(R"(rc=(\d+))", 10s);
  ASSERT_TRUE(rc) << check.output();
  EXPECT_EQ(*rc, "0") << "promtool check metrics: " << check.output();
}

TEST_F(FusiondMetricsTest, ScrapesParseAndCountersFollowCloudsAndCalls) {
  auto fusiond = StartWithMetrics();
  ASSERT_TRUE(fusiond);
  const PrometheusText before = Scrape();
  ASSERT_TRUE(before.ok());
  ExpectTypedDocumentedAndNamed(before);
  ASSERT_TRUE(before.Has(kReceived)) << body_;
  EXPECT_EQ(before.Value(kReceived), 0.0);
  EXPECT_EQ(before.Value(kIntegrated), 0.0);

  // Clouds arrive: received, integrated, in the map, with a latency observed for each.
  TestPublisher publisher(domain_);
  ASSERT_TRUE(publisher.ok()) << publisher.error();
  ASSERT_TRUE(publisher.WaitForReader(10s));
  constexpr int kFrames = 4;
  for (int seq = 1; seq <= kFrames; ++seq) PublishBoardFrame(publisher, seq);
  TestCloud stranger;
  stranger.sensor_id = "not-configured";
  stranger.width = 1;
  stranger.xyz = {1.0f, 0.0f, 0.0f};
  ASSERT_TRUE(publisher.Publish(stranger));
  const PrometheusText after = ScrapeUntil([&](const PrometheusText& m) {
    return m.Value(kIntegrated) >= kFrames && m.Value(kInMap) >= kFrames &&
           m.Value(kUnknownSensor) >= 1;
  });
  EXPECT_EQ(after.Value(kReceived), kFrames);  // reliable ingest: none lost
  EXPECT_EQ(after.Value(kIntegrated), kFrames);
  EXPECT_EQ(after.Value(kUnknownSensor), 1.0);
  EXPECT_EQ(after.Value(R"(fusiond_clouds_received_total{sensor="unconfigured"})"), 1.0);
  EXPECT_EQ(after.Value("fusiond_integration_duration_seconds_count"), kFrames);
  EXPECT_GT(after.Value("fusiond_integration_duration_seconds_sum"), 0.0);
  EXPECT_EQ(after.Value("fusiond_dds_to_queryable_seconds_count"), kFrames);
  EXPECT_GE(after.Value("fusiond_render_duration_seconds_count"), 1.0);
  EXPECT_GT(after.Value("fusiond_map_leaves"), 0.0);
  EXPECT_GT(after.Value(R"(fusiond_beam_grid_memory_bytes{sensor="sr"})"), 0.0);

  // The same numbers GetStats answers (nothing moves now: no clouds, no snapshot due yet).
  const v1::Stats stats = Stats();
  const PrometheusText now = Scrape();
  EXPECT_EQ(now.Value(kIntegrated), stats.clouds_integrated());
  EXPECT_EQ(
      now.Value(kReceived) + now.Value(R"(fusiond_clouds_received_total{sensor="unconfigured"})"),
      stats.clouds_received());
  EXPECT_EQ(now.Value("fusiond_map_version"), stats.map_version());
  EXPECT_EQ(now.Value("fusiond_map_leaves"), stats.map_leaves());
  // Snapshots are written every second here: at least as many as GetStats saw.
  EXPECT_GE(now.Value("fusiond_snapshots_written_total"), stats.snapshots_saved());

  // Calls are counted by method and status code, and timed by method.
  const std::string get_stats_ok = RpcSeries("GetStats", "OK");
  const std::string get_stats_seconds =
      R"(fusiond_rpc_duration_seconds_count{method="GetStats",service="fusion.v1.FusionMap"})";
  const double calls_before = now.Value(get_stats_ok);
  EXPECT_GE(calls_before, 1.0);  // the Stats() above (scrapes are no RPCs)
  for (int i = 0; i < 3; ++i) (void)Stats();
  grpc::ClientContext context;
  context.set_deadline(In(5s));
  v1::CastRayRequest bad_ray;  // zero direction
  bad_ray.set_max_range_m(1.0);
  v1::CastRayResponse ray;
  ASSERT_EQ(stub_->CastRay(&context, bad_ray, &ray).error_code(),
            grpc::StatusCode::INVALID_ARGUMENT);
  const PrometheusText calls = Scrape();
  EXPECT_EQ(calls.Value(get_stats_ok), calls_before + 3);
  EXPECT_EQ(calls.Value(get_stats_seconds), calls_before + 3);
  EXPECT_EQ(calls.Value(RpcSeries("CastRay", "INVALID_ARGUMENT")), 1.0);
  EXPECT_FALSE(calls.Has(RpcSeries("CastRay", "OK")));

  EXPECT_EQ(fusiond->Stop(SIGTERM, 15s), 0);

  // Prometheus' own checker on the last scrape (histograms and call series filled in).
  ExpectPromtoolAccepts(body_, dir_ + "/metrics.txt");
}

TEST_F(FusiondMetricsTest, MetricsAreOffByDefault) {
  auto fusiond = Start();
  ASSERT_TRUE(fusiond);
  (void)Stats();
  EXPECT_EQ(fusiond->output().find("metrics on"), std::string::npos) << fusiond->output();
  EXPECT_EQ(fusiond->Stop(SIGTERM, 15s), 0);
}

TEST_F(FusiondMetricsTest, ABadOrTakenAddressIsRefusedNamingTheField) {
  std::ifstream in(config_);
  const std::string base((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  auto fusiond = StartWithMetrics();
  ASSERT_TRUE(fusiond);
  const std::string taken = "127.0.0.1:" + std::to_string(metrics_port_);
  const std::string bad_config = dir_ + "/bad.pbtxt";
  for (const std::string& address : {std::string("localhost:9464"), std::string("127.0.0.1:65536"),
                                     std::string("127.0.0.1"), std::string("[::1]:x"), taken}) {
    std::ofstream(bad_config) << base << "metrics { listen_address: \"" << address << "\" }\n";
    // Through a shell: the message goes to stderr ("fusiond: metrics.listen_address: ..."
    // for a bad value; a taken port is found once logging runs: a critical log line).
    Subprocess bad({"/bin/sh", "-c", kFusiond + " --config " + bad_config + " 2>&1"});
    EXPECT_TRUE(bad.WaitForOutput(R"((fusiond: |\[critical\] )metrics\.listen_address: )", 15s))
        << address << " gave: " << bad.output();
    EXPECT_EQ(bad.Wait(15s), 2) << address;
  }
  // The first one goes on serving.
  EXPECT_TRUE(PrometheusText::Parse(HttpGet(metrics_port_, "/metrics", &body_)).ok());
  EXPECT_EQ(fusiond->Stop(SIGTERM, 15s), 0);
}

// The repository (FUSION_SHARED_DATA_DIR is <repo>/../shared/data).
std::string RepoDir() {
  const std::string dir = FUSION_SHARED_DATA_DIR;
  return dir.substr(0, dir.size() - std::string("/../shared/data").size());
}

std::string ReadFile(const std::string& path) {
  std::ifstream in(path);
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

// The dashboard and the alerts ask only for metrics fusiond exposes (a renamed metric would
// leave an empty panel or an alert that never fires), and Prometheus' tools accept the files.
TEST_F(FusiondMetricsTest, DashboardAndAlertsUseOnlyExposedMetrics) {
  auto fusiond = StartWithMetrics();
  ASSERT_TRUE(fusiond);
  (void)Stats();  // a family without series is left out: one call for the RPC families
  const PrometheusText metrics = Scrape();
  ASSERT_TRUE(metrics.ok());
  EXPECT_EQ(fusiond->Stop(SIGTERM, 15s), 0);
  const std::string dashboard = RepoDir() + "/docker/grafana/fusiond-dashboard.json";
  const std::string alerts = RepoDir() + "/docker/fusiond-alerts.yml";
  for (const std::string& file : {dashboard, alerts}) {
    const std::string text = ReadFile(file);
    ASSERT_FALSE(text.empty()) << file;
    const std::regex name(R"(\bfusiond_[a-z_]+)");
    int names = 0;
    for (auto it = std::sregex_iterator(text.begin(), text.end(), name);
         it != std::sregex_iterator(); ++it, ++names) {
      std::string family = it->str();
      for (const char* suffix : {"_bucket", "_sum", "_count"}) {
        const std::string s = suffix;
        if (!metrics.types.count(family) && family.size() > s.size() &&
            family.compare(family.size() - s.size(), s.size(), s) == 0) {
          family.resize(family.size() - s.size());
        }
      }
      EXPECT_TRUE(metrics.types.count(family)) << file << " asks for " << it->str();
    }
    EXPECT_GE(names, 5) << file;
  }
  Subprocess json({"/bin/sh", "-c",
                   "/usr/bin/python3 -c 'import json,sys; json.load(open(sys.argv[1]))' '" +
                       dashboard + "' 2>&1; echo rc=$?"});
  const auto json_rc = json.WaitForOutput(R"(rc=(\d+))", 10s);
  ASSERT_TRUE(json_rc) << json.output();
  EXPECT_EQ(*json_rc, "0") << dashboard << " is not JSON: " << json.output();

  Subprocess which({"/bin/sh", "-c", "command -v promtool || echo none"});
  const auto promtool = which.WaitForOutput(R"((\S+)\n)", 5s);
  (void)which.Wait(5s);
  if (!promtool || *promtool == "none")
    GTEST_SKIP() << "promtool not installed (package 'prometheus')";
  Subprocess check(
      {"/bin/sh", "-c",
       *promtool + " check config '" + RepoDir() + "/docker/prometheus.yml' 2>&1; echo rc=$?"});
  const auto rc = check.WaitForOutput(R"(rc=(\d+))", 10s);
  ASSERT_TRUE(rc) << check.output();
  EXPECT_EQ(*rc, "0") << check.output();
}

}  // namespace
