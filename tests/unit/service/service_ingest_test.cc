// Sample validation, the bounded per-sensor queues and the snapshot hub's change log.
#include <gtest/gtest.h>

#include <atomic>
#include <cmath>
#include <limits>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include "fusion/service/conversions.h"
#include "fusion/service/ingest_queues.h"
#include "fusion/service/map_snapshot.h"
#include "fusion/service/validation.h"

namespace fusion::service {
namespace {

// A valid 2 x 1 cloud of sensor "sr"; tests break one thing at a time.
struct Sample {
  std::string id = "sr";
  std::vector<float> xyz = {0.f, 0.f, 1.f, 0.f, 0.1f, 1.f};
  std::vector<std::uint8_t> beyond;
  fusion_dds_PointCloud msg{};
  Sample() {
    msg.width = 2;
    msg.height = 1;
    msg.T_world_sensor.qw = 1.0;
  }
  const fusion_dds_PointCloud& Get() {
    msg.sensor_id = id.data();
    msg.xyz._buffer = xyz.data();
    msg.xyz._length = static_cast<std::uint32_t>(xyz.size());
    msg.beyond_range._buffer = beyond.empty() ? nullptr : beyond.data();
    msg.beyond_range._length = static_cast<std::uint32_t>(beyond.size());
    return msg;
  }
};

std::optional<RejectReason> Check(Sample& s, IngestLimits limits = {},
                                  std::string* detail_out = nullptr) {
  std::string detail;
  const auto reason = ValidateSample(
      s.Get(), limits, [](const std::string& id) { return id == "sr"; }, &detail);
  if (detail_out != nullptr) *detail_out = detail;
  if (reason) {
    EXPECT_FALSE(detail.empty());
  }
  return reason;
}

TEST(ServiceIngestTest, ValidSampleIsAcceptedAndConverted) {
  Sample s;
  s.beyond = {0, 1};
  s.msg.T_world_sensor.tx = 2.0;
  EXPECT_EQ(Check(s), std::nullopt);
  const Cloud cloud = CloudFromDds(s.Get());
  EXPECT_EQ(cloud.sensor_id, "sr");
  EXPECT_EQ(cloud.xyz.size(), 6u);
  EXPECT_EQ(cloud.beyond_range.size(), 2u);
  EXPECT_DOUBLE_EQ(cloud.T_world_published.translation().x(), 2.0);
}

TEST(ServiceIngestTest, EveryMalformedShapeHasItsReason) {
  {
    Sample s;
    s.id = "";
    EXPECT_EQ(Check(s), RejectReason::kEmptySensorId);
  }
  {
    Sample s;
    s.id = "ghost";
    EXPECT_EQ(Check(s), RejectReason::kUnknownSensor);
  }
  {
    Sample s;
    s.xyz.pop_back();
    EXPECT_EQ(Check(s), RejectReason::kPointCountMismatch);
  }
  {
    Sample s;
    s.msg.height = 2;  // 4 points declared, 2 sent
    EXPECT_EQ(Check(s), RejectReason::kPointCountMismatch);
  }
  {
    Sample s;
    s.beyond = {1};
    EXPECT_EQ(Check(s), RejectReason::kBeyondRangeMismatch);
  }
  {
    Sample s;
    s.msg.width = 0;
    EXPECT_EQ(Check(s), RejectReason::kTooManyPoints);
  }
  {
    Sample s;
    s.msg.width = 0xffffffffu;  // width * height must not overflow into a small number
    s.msg.height = 0xffffffffu;
    EXPECT_EQ(Check(s), RejectReason::kTooManyPoints);
  }
  {
    Sample s;
    IngestLimits limits;
    limits.max_points = 1;
    EXPECT_EQ(Check(s, limits), RejectReason::kTooManyPoints);
  }
}

TEST(ServiceIngestTest, EveryMalformedPoseHasItsReason) {
  {
    Sample s;
    s.msg.T_world_sensor.qz = std::numeric_limits<double>::infinity();
    EXPECT_EQ(Check(s), RejectReason::kNonFinitePose);
  }
  {
    Sample s;
    s.msg.T_world_sensor.ty = std::nan("");
    EXPECT_EQ(Check(s), RejectReason::kNonFinitePose);
  }
  {
    Sample s;
    s.msg.T_world_sensor.qw = 0.99;  // |q| = 0.99: outside the 1e-3 tolerance
    EXPECT_EQ(Check(s), RejectReason::kNonUnitQuaternion);
    s.msg.T_world_sensor.qw = 0.9999;  // inside
    EXPECT_EQ(Check(s), std::nullopt);
  }
  {
    Sample s;
    s.msg.T_world_sensor.tz = -1e6;
    EXPECT_EQ(Check(s), RejectReason::kAbsurdTranslation);
  }
}

TEST(ServiceIngestTest, APoseBeyondTheMapsKeysIsOutsideMap) {
  {
    // Beyond the map's keys at 2 cm (+-655.36 m), well within max_abs_translation_m.
    IngestLimits limits;
    limits.map_resolution_m = 0.02;
    Sample s;
    s.msg.T_world_sensor.tx = 655.0;
    EXPECT_EQ(Check(s, limits), std::nullopt);
    s.msg.T_world_sensor.tx = 700.0;
    EXPECT_EQ(Check(s, limits), RejectReason::kOutsideMap);
    s.msg.T_world_sensor.tx = 0.0;
    s.msg.T_world_sensor.ty = -5000.0;
    EXPECT_EQ(Check(s, limits), RejectReason::kOutsideMap);
    limits.map_resolution_m = 0.2;  // +-6553.6 m
    EXPECT_EQ(Check(s, limits), std::nullopt);
  }
}

TEST(ServiceIngestTest, ReasonNamesAreDistinct) {
  std::set<std::string> names;
  for (std::size_t i = 0; i < kRejectReasonCount; ++i) {
    names.insert(RejectReasonName(static_cast<RejectReason>(i)));
  }
  EXPECT_EQ(names.size(), kRejectReasonCount);
  EXPECT_EQ(names.count("unknown_reason"), 0u);
}

// An id with a newline once forged a second log line; a 10 KB id was logged whole.
TEST(ServiceIngestTest, UntrustedTextIsEscapedAndTruncatedForTheLog) {
  EXPECT_EQ(LoggableText("sr3000"), "sr3000");
  EXPECT_EQ(LoggableText("a\n[error] forged"), "a\\n[error] forged");
  EXPECT_EQ(LoggableText(std::string("t\tb\\\x1b[31m\xff", 10)), "t\\x09b\\\\\\x1b[31m\\xff");
  const std::string long_id(10'000, 'x');
  EXPECT_EQ(LoggableText(long_id), std::string(64, 'x') + "...(10000 bytes)");
  Sample s;
  s.id = "ghost\nINFO all fine";
  std::string detail;
  ASSERT_EQ(Check(s, IngestLimits{}, &detail), RejectReason::kUnknownSensor);
  EXPECT_EQ(detail.find('\n'), std::string::npos) << detail;
  EXPECT_NE(detail.find("ghost\\nINFO"), std::string::npos) << detail;
}

Cloud MakeCloud(const std::string& id, std::uint64_t seq) {
  Cloud c;
  c.sensor_id = id;
  c.sequence_number = seq;
  return c;
}

TEST(ServiceIngestTest, QueuesKeepTheNewestAndCountDrops) {
  IngestQueues queues({{"a", 2}, {"b", 1}});
  for (std::uint64_t seq = 1; seq <= 5; ++seq) queues.Push(MakeCloud("a", seq));
  queues.Push(MakeCloud("b", 7));
  queues.Push(MakeCloud("ghost", 1));  // not configured: ignored
  EXPECT_EQ(queues.Pending(), 3u);
  std::vector<Cloud> out;
  ASSERT_TRUE(queues.PopAll(&out, std::chrono::steady_clock::now()));
  ASSERT_EQ(out.size(), 3u);
  EXPECT_EQ(out[0].sequence_number, 4u);  // oldest first within a sensor
  EXPECT_EQ(out[1].sequence_number, 5u);
  EXPECT_EQ(out[2].sequence_number, 7u);
  EXPECT_EQ(queues.counters("a")->received, 5u);
  EXPECT_EQ(queues.counters("a")->dropped, 3u);
  EXPECT_EQ(queues.counters("b")->dropped, 0u);
  EXPECT_EQ(queues.counters("ghost"), nullptr);

  queues.CountRejected("a", RejectReason::kNonFinitePose);
  queues.CountRejected("ghost", RejectReason::kUnknownSensor);
  EXPECT_EQ(queues.counters("a")->rejected.Total(), 1u);
  EXPECT_EQ(queues.all_rejected().Total(), 2u);

  out.clear();
  const auto start = std::chrono::steady_clock::now();
  EXPECT_FALSE(queues.PopAll(&out, start + std::chrono::milliseconds(30)));
  EXPECT_GE(std::chrono::steady_clock::now() - start, std::chrono::milliseconds(25));
}

TEST(ServiceIngestTest, ReliableQueuesWaitForRoomAndLoseNothing) {
  IngestQueues queues({{"a", 2}});
  std::atomic<bool> stop{false};
  std::atomic<std::uint64_t> pushed{0};
  std::thread producer([&] {
    for (std::uint64_t seq = 1; seq <= 50; ++seq) {
      EXPECT_TRUE(queues.Push(MakeCloud("a", seq), &stop));
      EXPECT_LE(queues.Pending(), 2u);
      pushed = seq;
    }
  });
  std::vector<std::uint64_t> taken;
  std::vector<Cloud> out;
  while (taken.size() < 50) {
    out.clear();
    queues.PopAll(&out, std::chrono::steady_clock::now() + std::chrono::milliseconds(200));
    for (const auto& cloud : out) taken.push_back(cloud.sequence_number);
  }
  producer.join();
  for (std::uint64_t i = 0; i < taken.size(); ++i) EXPECT_EQ(taken[i], i + 1);
  EXPECT_EQ(queues.counters("a")->received, 50u);
  EXPECT_EQ(queues.counters("a")->dropped, 0u);

  // A full queue and a stop: the waiting push gives up, counted as a drop.
  ASSERT_TRUE(queues.Push(MakeCloud("a", 51), &stop));
  ASSERT_TRUE(queues.Push(MakeCloud("a", 52), &stop));
  std::thread blocked([&] { EXPECT_FALSE(queues.Push(MakeCloud("a", 53), &stop)); });
  std::this_thread::sleep_for(std::chrono::milliseconds(50));
  stop = true;
  blocked.join();
  EXPECT_EQ(queues.counters("a")->dropped, 1u);
  EXPECT_EQ(queues.Pending(), 2u);
}

std::shared_ptr<const MapSnapshot> Version(std::uint64_t v) {
  auto s = std::make_shared<MapSnapshot>();
  s->version = v;
  s->tree = std::make_shared<octomap::OcTree>(0.1);
  return s;
}

MapChanges Changes(std::uint64_t v, std::vector<MapRegion> regions, bool reset = false) {
  return {v, reset, std::move(regions)};
}

TEST(ServiceIngestTest, HubLogsChangesAndForgetsTheOldest) {
  SnapshotHub hub(/*max_logged_regions=*/3);
  std::atomic<int> notified{0};
  const int id = hub.Subscribe([&] { ++notified; });
  const MapRegion a{MortonOf(octomap::OcTreeKey(1, 1, 1)), 16},
      b{MortonOf(octomap::OcTreeKey(2, 2, 2)), 16}, c{MortonOf(octomap::OcTreeKey(3, 3, 3)), 16};
  hub.Publish(Version(1), Changes(1, {a, b}));
  hub.Publish(Version(2), Changes(2, {b}));
  EXPECT_EQ(hub.Current()->version, 2u);
  std::vector<MapRegion> regions;
  ASSERT_TRUE(hub.ChangedSince(0, &regions));
  EXPECT_EQ(regions.size(), 2u);  // deduplicated
  ASSERT_TRUE(hub.ChangedSince(1, &regions));
  ASSERT_EQ(regions.size(), 1u);
  EXPECT_EQ(regions[0], b);
  hub.Publish(Version(3), Changes(3, {c}));  // 4 regions > 3: version 1 is forgotten
  EXPECT_FALSE(hub.ChangedSince(0, &regions));
  EXPECT_TRUE(hub.ChangedSince(1, &regions));
  hub.Publish(Version(4), Changes(4, {}, /*reset=*/true));  // nothing before 4 is known
  EXPECT_FALSE(hub.ChangedSince(3, &regions));
  // Subscribers hear of the publishes on the hub's thread, possibly several in one call.
  hub.Flush();
  const int heard = notified.load();
  EXPECT_GE(heard, 1);
  EXPECT_LE(heard, 4);
  hub.Publish(Version(5), Changes(5, {a}));
  hub.Flush();
  EXPECT_GT(notified.load(), heard);
  const int before_close = notified.load();
  hub.Unsubscribe(id);
  hub.Close();
  hub.Flush();
  EXPECT_EQ(notified.load(), before_close);
  EXPECT_TRUE(hub.closed());
}

Cloud CloudOfBytes(const std::string& id, std::uint64_t seq, std::size_t points) {
  Cloud c = MakeCloud(id, seq);
  c.xyz.resize(3 * points);
  return c;
}

TEST(ServiceIngestTest, QueuesAreBoundedInBytesAcrossSensors) {
  // 12 kB clouds (1000 points); 30 kB for all queues together, depth 16 each.
  IngestQueues queues({{"a", 16}, {"b", 16}}, 30'000);
  for (std::uint64_t seq = 1; seq <= 5; ++seq) queues.Push(CloudOfBytes("a", seq, 1000));
  EXPECT_EQ(queues.Pending(), 2u) << "best effort: the oldest dropped to stay within the bytes";
  EXPECT_EQ(queues.counters("a")->dropped, 3u);
  EXPECT_EQ(queues.queued_bytes(), 24'000u);
  // A sensor with an empty queue may always queue one cloud, even over the bound.
  EXPECT_TRUE(queues.Push(CloudOfBytes("b", 1, 1000)));
  EXPECT_EQ(queues.queued_bytes(), 36'000u);
  EXPECT_EQ(queues.counters("b")->dropped, 0u);
  std::vector<Cloud> out;
  ASSERT_TRUE(queues.PopAll(&out, std::chrono::steady_clock::now()));
  EXPECT_EQ(out.size(), 3u);
  EXPECT_EQ(queues.queued_bytes(), 0u);
}

TEST(ServiceIngestTest, ReliableQueuesWaitForBytesToFree) {
  IngestQueues queues({{"a", 16}}, 30'000);
  std::atomic<bool> stop{false};
  std::atomic<int> pushed{0};
  std::thread producer([&] {
    for (std::uint64_t seq = 1; seq <= 6; ++seq) {
      EXPECT_TRUE(queues.Push(CloudOfBytes("a", seq, 1000), &stop));
      ++pushed;
    }
  });
  std::this_thread::sleep_for(std::chrono::milliseconds(200));
  EXPECT_EQ(pushed, 2) << "the third cloud would exceed 30 kB: Push waits";
  std::vector<Cloud> out;
  std::uint64_t taken = 0;
  while (taken < 6) {
    out.clear();
    if (queues.PopAll(&out, std::chrono::steady_clock::now() + std::chrono::seconds(2))) {
      for (const Cloud& c : out) EXPECT_EQ(c.sequence_number, ++taken);  // none lost, in order
    }
    EXPECT_LE(queues.queued_bytes(), 30'000u);
  }
  producer.join();
  EXPECT_EQ(queues.counters("a")->dropped, 0u);
}

}  // namespace
}  // namespace fusion::service
