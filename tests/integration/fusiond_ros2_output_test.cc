// fusiond's ROS 2 output seen from the other DDS: a real fusiond (Cyclone DDS; the
// FusiondServiceTest fixture, tests/support/fusiond_fixture.h: 127.0.0.1:0, a private domain,
// loopback only) maps simulated SR-3000 clouds of the board scene, and Fast DDS subscribers
// (ROS 2's default DDS; tests/support/fastdds_participant.h, types by fastddsgen from idl/ros2:
// tests/support/ros2_fastdds.cmake) read octomap_msgs/Octomap from rt/octomap_binary and
// rt/octomap_full and the occupied centres from rt/octomap_point_cloud_centers. The maps they read
// back the way octomap_msgs' msgToMap does equal the .bt / .ot snapshots fetched over gRPC, and a
// subscriber that joins late still gets the last map (transient local).
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>
#include <octomap/AbstractOcTree.h>
#include <octomap/OcTree.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <csignal>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <memory>
#include <sstream>
#include <string>
#include <thread>
#include <tuple>
#include <vector>

#include "../support/fusiond_fixture.h"
#include "../support/http_get.h"
#include "../support/prometheus_text.h"
#include "fusion/v1/map_service.grpc.pb.h"

#if FUSION_HAVE_FASTDDS
#include "../support/fastdds_octomap.h"
#include "sensor_msgsPubSubTypes.h"
#endif

namespace {

using namespace fusion::testing;  // NOLINT: the fixture and its helpers
using namespace std::chrono_literals;
namespace v1 = fusion::v1;

std::string FetchSnapshot(v1::FusionMap::Stub& stub, v1::GetSnapshotRequest::Format format) {
  grpc::ClientContext context;
  context.set_deadline(In(10s));
  v1::GetSnapshotRequest request;
  request.set_format(format);
  auto reader = stub.GetSnapshot(&context, request);
  std::string data;
  v1::SnapshotChunk chunk;
  while (reader->Read(&chunk)) data += chunk.data();
  const auto status = reader->Finish();
  EXPECT_TRUE(status.ok()) << status.error_message();
  return data;
}

// A leaf as OctoMap's leaf iterator visits it: key, depth and log-odds.
using Leaf = std::tuple<std::uint16_t, std::uint16_t, std::uint16_t, unsigned, float>;

std::vector<Leaf> LeavesOf(const octomap::OcTree& tree) {
  std::vector<Leaf> leaves;
  for (auto it = tree.begin_leafs(), end = tree.end_leafs(); it != end; ++it) {
    const octomap::OcTreeKey key = it.getKey();
    leaves.emplace_back(key[0], key[1], key[2], it.getDepth(), it->getLogOdds());
  }
  return leaves;
}

std::vector<std::array<float, 3>> OccupiedCentres(const octomap::OcTree& tree) {
  std::vector<std::array<float, 3>> centres;
  for (auto it = tree.begin_leafs(), end = tree.end_leafs(); it != end; ++it) {
    if (!tree.isNodeOccupied(*it)) continue;
    const octomap::point3d c = it.getCoordinate();
    centres.push_back({c.x(), c.y(), c.z()});
  }
  std::sort(centres.begin(), centres.end());
  return centres;
}

#if FUSION_HAVE_FASTDDS
using PointCloud2 = sensor_msgs::msg::dds_::PointCloud2_;

// The map a snapshot file holds (.bt: readBinary; .ot: AbstractOcTree::read).
std::unique_ptr<octomap::OcTree> SnapshotToMap(const std::string& file, bool binary) {
  std::istringstream in(file);
  if (binary) {
    auto tree = std::make_unique<octomap::OcTree>(0.1);
    return tree->readBinary(in) ? std::move(tree) : nullptr;
  }
  std::unique_ptr<octomap::AbstractOcTree> read(octomap::AbstractOcTree::read(in));
  auto* octree = dynamic_cast<octomap::OcTree*>(read.get());
  if (octree != nullptr) read.release();
  return std::unique_ptr<octomap::OcTree>(octree);
}

// Whether the message holds the snapshot `file`'s map: its data is the file without the file's
// header, and OctoMap reads the same leaves with the same values from both. *why says why not.
bool SameMap(const Octomap& msg, const std::string& file, std::string* why) {
  const std::string data(msg.data().begin(), msg.data().end());
  const std::string header = file.substr(0, file.size() - std::min(file.size(), data.size()));
  if (data.empty() || file.size() <= data.size() ||
      file.compare(header.size(), data.size(), data) != 0 || header.size() < 5 ||
      header.compare(header.size() - 5, 5, "data\n") != 0) {
    *why = "data (" + std::to_string(data.size()) + " bytes) is not the snapshot (" +
           std::to_string(file.size()) + " bytes) after its header";
    return false;
  }
  const auto from_msg = MsgToMap(msg);
  const auto from_file = SnapshotToMap(file, msg.binary());
  if (!from_msg || !from_file) {
    *why = "OctoMap could not read the message or the snapshot";
    return false;
  }
  if (LeavesOf(*from_msg) != LeavesOf(*from_file)) {
    *why = "the leaves differ";
    return false;
  }
  return true;
}

std::vector<std::array<float, 3>> CentresOf(const PointCloud2& cloud) {
  std::vector<std::array<float, 3>> centres(cloud.width());
  for (std::size_t i = 0; i < centres.size(); ++i) {
    std::memcpy(centres[i].data(), cloud.data().data() + i * cloud.point_step(), 3 * sizeof(float));
  }
  std::sort(centres.begin(), centres.end());
  return centres;
}

class Ros2OutputTest : public FusiondServiceTest {
 protected:
  void SetUp() override {
    FusiondServiceTest::SetUp();
    std::ofstream(config_, std::ios::app)
        << "ros2 { map_frame: \"world\" octomap_rate_hz: 5 octomap_full: true "
        << "point_cloud_centers: true }\n";
  }

  // Waits until every received cloud is in the map and the version stays (the clouds stopped:
  // the worker renders what it still holds, then the map keeps its last version). Returns it.
  std::uint64_t WaitForTheLastVersion() {
    std::uint64_t last = UINT64_MAX;
    for (const auto end = std::chrono::steady_clock::now() + 30s;
         std::chrono::steady_clock::now() < end; std::this_thread::sleep_for(500ms)) {
      const v1::Stats stats = Stats();
      const bool all_in =
          stats.clouds_received() > 0 && stats.clouds_in_map() == stats.clouds_received();
      if (all_in && stats.map_version() == last) return last;
      last = all_in ? stats.map_version() : UINT64_MAX;
    }
    ADD_FAILURE() << "the map did not settle within 30 s";
    return 0;
  }
};

TEST_F(Ros2OutputTest, FastDdsSubscribersReadTheSnapshotsMapAlsoWhenTheyJoinLate) {
  auto fusiond = Start();
  ASSERT_TRUE(fusiond);
  FastDdsParticipant early(domain_, "fusion_test_early");
  ASSERT_TRUE(early.ok());
  auto* binary_reader =
      early.CreateReader<octomap_msgs::msg::dds_::Octomap_PubSubType>("rt/octomap_binary");
  auto* full_reader =
      early.CreateReader<octomap_msgs::msg::dds_::Octomap_PubSubType>("rt/octomap_full");
  auto* centres_reader = early.CreateReader<sensor_msgs::msg::dds_::PointCloud2_PubSubType>(
      "rt/octomap_point_cloud_centers");
  ASSERT_TRUE(binary_reader && full_reader && centres_reader);
  {
    TestPublisher publisher(domain_);
    ASSERT_TRUE(publisher.WaitForReader(10s));
    ASSERT_GT(MapTheBoard(publisher), 0u);
  }
  // The clouds stopped: the map settles on its last version, which fusiond publishes once.
  const std::uint64_t last_version = WaitForTheLastVersion();
  ASSERT_GT(last_version, 0u);
  Octomap binary, full;
  std::string bt, ot, why = "no message";
  bool have_binary = false, have_full = false, same = false;
  for (const auto end = std::chrono::steady_clock::now() + 20s;
       !same && std::chrono::steady_clock::now() < end;) {
    have_binary = TakeNewest(binary_reader, &binary, 300ms) || have_binary;
    have_full = TakeNewest(full_reader, &full, 300ms) || have_full;
    bt = FetchSnapshot(*stub_, v1::GetSnapshotRequest::FORMAT_BT);
    ot = FetchSnapshot(*stub_, v1::GetSnapshotRequest::FORMAT_OT);
    same = have_binary && have_full && SameMap(binary, bt, &why) && SameMap(full, ot, &why);
  }
  ASSERT_TRUE(same) << why;
  // At 5 Hz, 1.5 s are 7 chances to publish: an unchanged map is not published again.
  Octomap again;
  EXPECT_FALSE(TakeSample(binary_reader, &again, 1500ms)) << "an unchanged map published again";
  EXPECT_TRUE(binary.binary());
  EXPECT_FALSE(full.binary());
  for (const Octomap* msg : {&binary, &full}) {
    EXPECT_EQ(msg->header().frame_id(), "world");
    EXPECT_EQ(msg->id(), "OcTree");
    EXPECT_DOUBLE_EQ(msg->resolution(), 0.05);
    const auto now_s = std::chrono::duration_cast<std::chrono::seconds>(
                           std::chrono::system_clock::now().time_since_epoch())
                           .count();
    EXPECT_NEAR(static_cast<double>(msg->header().stamp().sec()), static_cast<double>(now_s), 60.0);
  }
  const auto from_bt = SnapshotToMap(bt, true);
  ASSERT_TRUE(from_bt);
  ASSERT_NE(from_bt->search(kOnBoard.x(), kOnBoard.y(), kOnBoard.z()), nullptr);
  EXPECT_TRUE(from_bt->isNodeOccupied(from_bt->search(kOnBoard.x(), kOnBoard.y(), kOnBoard.z())));

  // The occupied centres of the same version (written after the two maps).
  const auto expected_centres = OccupiedCentres(*from_bt);
  ASSERT_FALSE(expected_centres.empty());
  PointCloud2 cloud;
  bool same_centres = false;
  for (const auto end = std::chrono::steady_clock::now() + 10s;
       !same_centres && std::chrono::steady_clock::now() < end;) {
    if (TakeNewest(centres_reader, &cloud, 300ms))
      same_centres = CentresOf(cloud) == expected_centres;
  }
  ASSERT_TRUE(same_centres) << "no cloud of the " << expected_centres.size() << " occupied centres";
  EXPECT_EQ(cloud.header().frame_id(), "world");
  EXPECT_EQ(cloud.height(), 1u);
  EXPECT_EQ(cloud.point_step(), 12u);
  ASSERT_EQ(cloud.fields().size(), 3u);
  for (std::size_t i = 0; i < 3; ++i) {
    EXPECT_EQ(cloud.fields()[i].name(), std::string(1, "xyz"[i]));
    EXPECT_EQ(cloud.fields()[i].offset(), 4 * i);
    EXPECT_EQ(cloud.fields()[i].datatype(), 7);  // FLOAT32
    EXPECT_EQ(cloud.fields()[i].count(), 1u);
  }

  // A subscriber that joins now, with the map unchanged: the writers' history (transient local,
  // keep last 1) gives it the last map, once. It is configured as docs/ros2.md tells ROS 2 nodes
  // on Fast DDS: by the XML profile docker/fastdds-loopback.xml.
  const std::string profile =
      (std::filesystem::path(__FILE__).parent_path() / "../../docker/fastdds-loopback.xml")
          .string();
  FastDdsParticipant late(domain_, profile, "fusion_loopback");
  ASSERT_TRUE(late.ok());
  auto* late_binary =
      late.CreateReader<octomap_msgs::msg::dds_::Octomap_PubSubType>("rt/octomap_binary");
  auto* late_full =
      late.CreateReader<octomap_msgs::msg::dds_::Octomap_PubSubType>("rt/octomap_full");
  ASSERT_TRUE(late_binary && late_full);
  Octomap late_map;
  ASSERT_TRUE(TakeSample(late_binary, &late_map, 15s)) << "the late subscriber got no binary map";
  EXPECT_TRUE(SameMap(late_map, bt, &why)) << why;
  EXPECT_FALSE(TakeSample(late_binary, &late_map, 1s)) << "more than the last map";
  ASSERT_TRUE(TakeSample(late_full, &late_map, 15s)) << "the late subscriber got no full map";
  EXPECT_TRUE(SameMap(late_map, ot, &why)) << why;
  EXPECT_EQ(Stats().map_version(), last_version) << "the map changed during the test";
  EXPECT_EQ(fusiond->Stop(SIGTERM, 15s), 0);
}
// fusiond's /metrics counts what the ROS 2 output does, per topic: the map versions it wrote,
// their data's bytes, failures, and the DDS readers matched with each writer now (a Fast DDS
// subscriber on two of the three topics, then none once it leaves).
TEST_F(Ros2OutputTest, MetricsCountPublicationsBytesAndMatchedSubscribersPerTopic) {
  std::ofstream(config_, std::ios::app) << "metrics { listen_address: \"127.0.0.1:0\" }\n";
  auto fusiond = Start();
  ASSERT_TRUE(fusiond);
  const auto port = fusiond->WaitForOutput(R"(fusiond metrics on 127\.0\.0\.1:(\d+))", 5s);
  ASSERT_TRUE(port) << fusiond->output();
  std::string body;
  const auto scrape = [&] {
    std::string head;
    body = HttpGet(std::stoi(*port), "/metrics", &head);
    auto parsed = PrometheusText::Parse(body);
    EXPECT_TRUE(parsed.ok()) << parsed.error;
    return parsed;
  };
  const auto series = [](const char* family, const char* topic) {
    return std::string(family) + "{topic=\"" + topic + "\"}";
  };
  const auto scrape_until = [&](const std::function<bool(const PrometheusText&)>& done) {
    PrometheusText m = scrape();
    for (const auto end = std::chrono::steady_clock::now() + 15s;
         !done(m) && std::chrono::steady_clock::now() < end; m = scrape()) {
      std::this_thread::sleep_for(100ms);
    }
    EXPECT_TRUE(done(m)) << body;
    return m;
  };
  const char* const kSubscribers = "fusiond_ros2_matched_subscribers";
  {
    FastDdsParticipant subscriber(domain_, "fusion_test_metrics");
    ASSERT_TRUE(subscriber.ok());
    auto* binary_reader =
        subscriber.CreateReader<octomap_msgs::msg::dds_::Octomap_PubSubType>("rt/octomap_binary");
    auto* full_reader =
        subscriber.CreateReader<octomap_msgs::msg::dds_::Octomap_PubSubType>("rt/octomap_full");
    ASSERT_TRUE(binary_reader && full_reader);
    PrometheusText m = scrape_until([&](const PrometheusText& m) {
      return m.Value(series(kSubscribers, "rt/octomap_binary")) == 1 &&
             m.Value(series(kSubscribers, "rt/octomap_full")) == 1;
    });
    EXPECT_EQ(m.Value(series(kSubscribers, "rt/octomap_point_cloud_centers")), 0);
    EXPECT_TRUE(m.Has(series(kSubscribers, "rt/octomap_point_cloud_centers")));
    EXPECT_EQ(m.types.at("fusiond_ros2_publications_total"), "counter");
    EXPECT_EQ(m.types.at(kSubscribers), "gauge");
    {
      TestPublisher publisher(domain_);
      ASSERT_TRUE(publisher.WaitForReader(10s));
      ASSERT_GT(MapTheBoard(publisher), 0u);
    }
    ASSERT_GT(WaitForTheLastVersion(), 0u);
    Octomap binary;
    ASSERT_TRUE(TakeNewest(binary_reader, &binary, 10s));
    const char* const kTopics[] = {"rt/octomap_binary", "rt/octomap_full",
                                   "rt/octomap_point_cloud_centers"};
    // The last version may still be on its way: wait until the three topics wrote it alike.
    m = scrape_until([&](const PrometheusText& m) {
      const double n = m.Value(series("fusiond_ros2_publications_total", kTopics[0]));
      return n >= 1 && m.Value(series("fusiond_ros2_publications_total", kTopics[1])) == n &&
             m.Value(series("fusiond_ros2_publications_total", kTopics[2])) == n;
    });
    const double versions = m.Value(series("fusiond_ros2_publications_total", kTopics[0]));
    for (const char* topic : kTopics) {
      EXPECT_EQ(m.Value(series("fusiond_ros2_publication_failures_total", topic)), 0) << topic;
      EXPECT_GT(m.Value(series("fusiond_ros2_published_bytes_total", topic)), 0) << topic;
    }
    // Every version's data: at least the last one's (the one the subscriber holds), and more when
    // several versions were written.
    const double binary_bytes = m.Value(series("fusiond_ros2_published_bytes_total", kTopics[0]));
    EXPECT_GE(binary_bytes, static_cast<double>(binary.data().size()));
    if (versions > 1) EXPECT_GT(binary_bytes, static_cast<double>(binary.data().size()));
  }
  // The subscriber left: its readers unmatch.
  scrape_until([&](const PrometheusText& m) {
    return m.Has(series(kSubscribers, "rt/octomap_binary")) &&
           m.Value(series(kSubscribers, "rt/octomap_binary")) == 0 &&
           m.Value(series(kSubscribers, "rt/octomap_full")) == 0;
  });
  EXPECT_EQ(fusiond->Stop(SIGTERM, 15s), 0);
}
#else
TEST(Ros2OutputTest, SkippedWithoutFastDds) {
  GTEST_SKIP() << "Fast DDS (libfastrtps-dev, libfastcdr-dev, fastddsgen) was not found at build "
                  "time";
}
#endif

}  // namespace
