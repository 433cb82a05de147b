// ROS 2 output: the fused map published as octomap_server publishes it, so that RViz's OctoMap
// display and any octomap_server client read it (docs/ros2.md): octomap_msgs/Octomap on
// rt/octomap_binary and rt/octomap_full, optionally the occupied leaves' centres as a
// sensor_msgs/PointCloud2 on rt/octomap_point_cloud_centers; reliable, transient local, keep
// last 1. A thread of its own takes the published map version (SnapshotHub::Current, as the
// snapshots do) at most rate_hz times a second, only when the version changed, so neither the
// queries nor the render ever wait for it.
#pragma once

#include <dds/dds.h>
#include <octomap/OcTree.h>

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "fusion/core/status.h"
#include "fusion/service/conversions.h"
#include "fusion/service/map_snapshot.h"
#include "fusion/v1/config.pb.h"

namespace fusion::service {

// The DDS topics (ROS 2's /octomap_binary, /octomap_full, /octomap_point_cloud_centers).
inline constexpr const char* kOctomapBinaryTopic = "rt/octomap_binary";
inline constexpr const char* kOctomapFullTopic = "rt/octomap_full";
inline constexpr const char* kOctomapCentersTopic = "rt/octomap_point_cloud_centers";

struct Ros2OutputOptions {
  static constexpr double kMaxRateHz = 100.0;
  double rate_hz = 0.0;  // 0: off (no writers)
  bool binary = true;
  bool full = false;
  bool point_cloud_centers = false;
  std::string map_frame = "map";  // header.frame_id
  StateThresholds thresholds;     // the binary map's classes (map.occupied / free_threshold)
  // How long one write may wait for a slow reliable reader (then it counts as failed).
  std::chrono::milliseconds write_timeout{2000};
  // Failures are logged at most once per interval (the others are counted).
  std::chrono::milliseconds log_interval{10000};

  [[nodiscard]] bool enabled() const {
    return rate_hz > 0.0 && (binary || full || point_cloud_centers);
  }
};

// The ros2 section's output fields (ros2_config.cc; ValidateConfig checks them). An error names
// the field ("ros2.octomap_rate_hz: ...").
[[nodiscard]] StatusOr<Ros2OutputOptions> Ros2OutputOptionsFromConfig(
    const fusion::v1::ServiceConfig& config);

// What one topic's writer did since the start (fusiond's metrics: docs/operations.md).
struct Ros2TopicStats {
  std::string topic;
  std::uint64_t publications = 0;  // map versions written
  std::uint64_t bytes = 0;         // of their data (the map, or the centres' points)
  std::uint64_t failures = 0;      // versions not written (serialising, too large, dds_write)
  std::uint32_t matched_subscribers = 0;  // DDS readers matched now
};

// octomap_msgs' conversions (conversions.h): binaryMapToMsg's data is what
// OcTree::writeBinaryData writes, fullMapToMsg's what OcTree::writeData writes.
[[nodiscard]] std::string OctomapBinaryData(const octomap::OcTree& tree, const StateThresholds& t);
[[nodiscard]] std::string OctomapFullData(const octomap::OcTree& tree);
// The centres of the occupied leaves (pruned ones: the centre of the coarse node, as
// octomap_server does), x y z in the map frame, metres.
[[nodiscard]] std::vector<float> OccupiedLeafCentres(const octomap::OcTree& tree);

class Ros2Output {
 public:
  Ros2Output(const SnapshotHub* hub, Ros2OutputOptions options);
  ~Ros2Output();
  Ros2Output(const Ros2Output&) = delete;
  Ros2Output& operator=(const Ros2Output&) = delete;

  // Creates the topics and writers in `participant` and starts the thread (nothing when the
  // options are not enabled()).
  [[nodiscard]] Status Start(dds_entity_t participant);
  // Stops the thread; the writers go with the participant.
  void Stop();

  // The configured topics' counts (none before Start or when off); thread-safe. Valid until
  // the participant that Start was given is deleted.
  [[nodiscard]] std::vector<Ros2TopicStats> TopicStats() const;

 private:
  enum class Content { kBinary, kFull, kCentres };
  struct Topic {
    const char* name;
    Content content;
    dds_entity_t writer = 0;  // 0: not configured
    std::atomic<std::uint64_t> publications{0};
    std::atomic<std::uint64_t> bytes{0};
    std::atomic<std::uint64_t> failures{0};
  };
  [[nodiscard]] Status CreateWriter(dds_entity_t participant, Topic* topic);
  void Loop();
  // Serialises and writes one version on every configured topic, each counted on its own.
  void Publish(const MapSnapshot& snapshot);
  // Serialises and writes one version on `topic`; *bytes: its data's size. An error names it.
  [[nodiscard]] Status PublishOn(const Topic& topic, const octomap::OcTree& tree,
                                 std::size_t* bytes);
  void CountFailure(Topic& topic, const Status& status);

  const SnapshotHub* hub_;
  Ros2OutputOptions options_;
  Topic topics_[3] = {{kOctomapBinaryTopic, Content::kBinary},
                      {kOctomapFullTopic, Content::kFull},
                      {kOctomapCentersTopic, Content::kCentres}};
  std::uint64_t last_version_ = 0;  // the version 0 (the empty map before any render) is skipped
  std::chrono::steady_clock::time_point last_failure_log_{};
  std::uint64_t unlogged_failures_ = 0;
  std::mutex stop_mutex_;
  std::condition_variable stop_cv_;
  bool stop_ = false;
  std::thread thread_;
};

}  // namespace fusion::service
