// Test helper: publishes point clouds on the fusion DDS topic, in-process, over the same
// loopback configuration fusiond uses.
#pragma once

#include <Eigen/Geometry>
#include <chrono>
#include <cstdint>
#include <string>
#include <thread>
#include <vector>

#include "fusion/dds/participant.h"
#include "fusion_dds.h"

namespace fusion::testing {

// A cloud as the test writes it; any field may be made inconsistent on purpose.
struct TestCloud {
  std::string sensor_id = "sr";
  std::uint64_t sequence_number = 0;
  double tx = 0, ty = 0, tz = 0, qx = 0, qy = 0, qz = 0, qw = 1;
  std::uint32_t width = 0;
  std::uint32_t height = 1;
  std::vector<float> xyz;
  std::vector<std::uint8_t> beyond_range;

  void SetPose(const Eigen::Isometry3d& T) {
    const Eigen::Quaterniond q(T.rotation());
    tx = T.translation().x();
    ty = T.translation().y();
    tz = T.translation().z();
    qx = q.x();
    qy = q.y();
    qz = q.z();
    qw = q.w();
  }
};

class TestPublisher {
 public:
  explicit TestPublisher(unsigned domain, const std::string& topic = "fusion/points") {
    participant_ = fusion::dds::CreateParticipant(domain, &error_);
    if (participant_ < 0) return;
    topic_ = dds_create_topic(participant_, &fusion_dds_PointCloud_desc, topic.c_str(), nullptr,
                              nullptr);
    if (topic_ < 0) {
      error_ = std::string("dds_create_topic: ") + dds_strretcode(topic_);
      return;
    }
    dds_qos_t* qos = dds_create_qos();
    dds_qset_reliability(qos, DDS_RELIABILITY_RELIABLE, DDS_SECS(1));
    dds_qset_history(qos, DDS_HISTORY_KEEP_LAST, 4);
    writer_ = dds_create_writer(participant_, topic_, qos, nullptr);
    dds_delete_qos(qos);
    if (writer_ < 0) error_ = std::string("dds_create_writer: ") + dds_strretcode(writer_);
  }
  ~TestPublisher() {
    if (participant_ > 0) dds_delete(participant_);
  }
  TestPublisher(const TestPublisher&) = delete;
  TestPublisher& operator=(const TestPublisher&) = delete;

  [[nodiscard]] bool ok() const { return writer_ > 0; }
  [[nodiscard]] const std::string& error() const { return error_; }

  bool WaitForReader(std::chrono::milliseconds timeout) {
    const auto end = std::chrono::steady_clock::now() + timeout;
    dds_publication_matched_status_t matched{};
    while (std::chrono::steady_clock::now() < end) {
      if (dds_get_publication_matched_status(writer_, &matched) == DDS_RETCODE_OK &&
          matched.current_count > 0) {
        return true;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    return false;
  }

  // Writes the cloud and waits until the readers acknowledged it.
  bool Publish(TestCloud& c) {
    return Write(c) && dds_wait_for_acks(writer_, DDS_SECS(5)) == DDS_RETCODE_OK;
  }

  // Writes the cloud (reliable: blocks while the reader holds the writer back).
  bool Write(TestCloud& c) {
    fusion_dds_PointCloud sample{};
    sample.sensor_id = c.sensor_id.data();
    sample.sequence_number = c.sequence_number;
    sample.T_world_sensor = {c.tx, c.ty, c.tz, c.qx, c.qy, c.qz, c.qw};
    sample.width = c.width;
    sample.height = c.height;
    sample.xyz._buffer = c.xyz.data();
    sample.xyz._length = sample.xyz._maximum = static_cast<std::uint32_t>(c.xyz.size());
    sample.beyond_range._buffer = c.beyond_range.data();
    sample.beyond_range._length = sample.beyond_range._maximum =
        static_cast<std::uint32_t>(c.beyond_range.size());
    return dds_write(writer_, &sample) == DDS_RETCODE_OK;
  }

 private:
  dds_entity_t participant_ = 0;
  dds_entity_t topic_ = 0;
  dds_entity_t writer_ = 0;
  std::string error_;
};

}  // namespace fusion::testing
