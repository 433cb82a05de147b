// Ingest memory under hostile DDS input (issue 14, defect 6): fusiond's resident memory while
//   A. a publisher sends clouds from many distinct, unconfigured sensor ids (each id used to
//      leave ~375 B of reader state behind while its writer lived), and
//   B. a reliable publisher writes large clouds faster than the worker integrates them (the
//      reader cache and the queues used to grow to gigabytes).
// Not a test: prints figures for BENCHMARKS.md. Loopback only, a private DDS domain.
//   ingest_memory_bench [--ids N] [--points N] [--seconds S] [--queued-mb MB]
#include <grpcpp/grpcpp.h>

#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>

#include "../../support/dds_publisher.h"
#include "../../support/subprocess.h"
#include "fusion/v1/map_service.grpc.pb.h"

namespace {

using fusion::testing::Subprocess;
using fusion::testing::TestCloud;
using fusion::testing::TestPublisher;
using namespace std::chrono_literals;

struct Options {
  int ids = 100000;
  int points = 1000000;
  double seconds = 15;
  int queued_mb = 256;
};

double RssMb(pid_t pid) {
  std::ifstream in("/proc/" + std::to_string(pid) + "/status");
  std::string line;
  while (std::getline(in, line)) {
    if (line.rfind("VmRSS:", 0) == 0) return std::atof(line.c_str() + 6) / 1024.0;
  }
  return 0.0;
}

struct Fusiond {
  std::unique_ptr<Subprocess> process;
  std::unique_ptr<fusion::v1::FusionMap::Stub> stub;
};

Fusiond Start(const std::string& dir, unsigned domain, const std::string& ingest) {
  const std::string config = dir + "/fusiond.pbtxt";
  std::ofstream(config) << "listen_address: \"127.0.0.1:0\"\ndds_domain: " << domain
                        << "\nlog_level: \"error\"\n"
                        << "sensors { id: \"sr\" preset: \"sr3000\" cols: 44 rows: 36 }\n"
                        << "map { resolution_m: 0.05 }\ningest { " << ingest << " }\n";
  Fusiond f;
  f.process = std::make_unique<Subprocess>(std::vector<std::string>{
      std::string(FUSION_BINARY_DIR) + "/service/fusiond", "--config", config});
  const auto port = f.process->WaitForOutput(R"(listening on 127\.0\.0\.1:(\d+))", 20s);
  if (!port) {
    std::fprintf(stderr, "fusiond did not start: %s\n", f.process->output().c_str());
    std::exit(1);
  }
  f.stub = fusion::v1::FusionMap::NewStub(
      grpc::CreateChannel("127.0.0.1:" + *port, grpc::InsecureChannelCredentials()));
  return f;
}

fusion::v1::Stats Stats(Fusiond& f) {
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + 10s);
  fusion::v1::Stats stats;
  (void)f.stub->GetStats(&context, fusion::v1::GetStatsRequest(), &stats);
  return stats;
}

void UnknownIds(const Options& o, const std::string& dir, unsigned domain) {
  Fusiond f = Start(dir, domain, "reliability: \"best_effort\"");
  TestPublisher publisher(domain);
  if (!publisher.WaitForReader(10s)) std::exit(1);
  const double before = RssMb(f.process->pid());
  TestCloud cloud;
  cloud.width = 1;
  cloud.xyz = {0.0f, 0.0f, 1.0f};
  for (int i = 0; i < o.ids; ++i) {
    cloud.sensor_id = "ghost-" + std::to_string(i);
    (void)publisher.Write(cloud);
    if (i % 20000 == 0) std::fprintf(stderr, "  %d ids written, fusiond %.1f MB\n", i, RssMb(f.process->pid()));
  }
  std::this_thread::sleep_for(2s);
  const double after = RssMb(f.process->pid());
  const auto stats = Stats(f);
  const auto it = stats.rejected_by_reason().find("unknown_sensor");
  const unsigned long long rejected = it == stats.rejected_by_reason().end() ? 0 : it->second;
  std::printf("A. %d unknown sensor ids (writer alive): fusiond RSS %.1f -> %.1f MB "
              "(%+.0f B per id), %llu counted as unknown_sensor\n",
              o.ids, before, after, (after - before) * 1048576.0 / o.ids, rejected);
  (void)f.process->Stop(SIGTERM, 15s);
}

void ReliableFlood(const Options& o, const std::string& dir, unsigned domain) {
  Fusiond f = Start(dir, domain, "reliability: \"reliable\" max_queued_mb: " +
                                     std::to_string(o.queued_mb));
  TestPublisher publisher(domain);
  if (!publisher.WaitForReader(10s)) std::exit(1);
  TestCloud cloud;
  cloud.width = static_cast<std::uint32_t>(o.points);
  cloud.xyz.resize(3 * static_cast<std::size_t>(o.points));
  for (int i = 0; i < o.points; ++i) {  // a fan of rays 2 m ahead
    cloud.xyz[3 * i] = 0.001f * static_cast<float>(i % 1000) - 0.5f;
    cloud.xyz[3 * i + 1] = 0.001f * static_cast<float>((i / 1000) % 1000) - 0.5f;
    cloud.xyz[3 * i + 2] = 2.0f;
  }
  const double start_rss = RssMb(f.process->pid());
  double peak = start_rss;
  const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(o.seconds);
  std::uint64_t written = 0;
  while (std::chrono::steady_clock::now() < end) {
    cloud.sequence_number = ++written;
    if (!publisher.Write(cloud)) break;
    peak = std::max(peak, RssMb(f.process->pid()));
  }
  const auto stats = Stats(f);
  std::printf("B. reliable, %d-point clouds (%.1f MB each) for %.0f s, max_queued_mb %d: "
              "%llu written, %llu received, %llu integrated; fusiond RSS %.0f MB at start, "
              "peak %.0f MB\n",
              o.points, o.points * 12.0 / 1048576.0, o.seconds, o.queued_mb,
              static_cast<unsigned long long>(written),
              static_cast<unsigned long long>(stats.clouds_received()),
              static_cast<unsigned long long>(stats.clouds_integrated()), start_rss, peak);
  (void)f.process->Stop(SIGTERM, 30s);
}

}  // namespace

int main(int argc, char** argv) {
  Options o;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    const auto next = [&] { return i + 1 < argc ? argv[++i] : "0"; };
    if (a == "--ids") o.ids = std::atoi(next());
    else if (a == "--points") o.points = std::atoi(next());
    else if (a == "--seconds") o.seconds = std::atof(next());
    else if (a == "--queued-mb") o.queued_mb = std::atoi(next());
    else {
      std::printf("usage: %s [--ids N (100000)] [--points N (1000000)] [--seconds S (15)] "
                  "[--queued-mb MB (256)]\n%s",
                  argv[0], "Prints fusiond's memory under hostile DDS input (A: unknown ids, "
                           "B: a reliable flood of large clouds).\n");
      return a == "--help" ? 0 : 2;
    }
  }
  const std::string dir = std::filesystem::temp_directory_path() / ("ingest_memory_bench_" +
                                                                    std::to_string(getpid()));
  std::filesystem::create_directories(dir);
  const unsigned domain = fusion::testing::PrivateDomainId(0);
  UnknownIds(o, dir, domain);
  ReliableFlood(o, dir, fusion::testing::PrivateDomainId(1));
  std::filesystem::remove_all(dir);
  return 0;
}
