// Clients' side of the DDS bus: a writer and a reader of the "fusion/points" topic
// (fusion_dds_PointCloud), in a participant of fusion/dds/participant.h (the configuration
// fusiond uses too).
#pragma once

#include <dds/dds.h>

#include <chrono>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "fusion/core/status.h"
#include "fusion/v1/recording.pb.h"
#include "fusion_dds.h"

namespace fusion::clients {

inline constexpr const char* kPointsTopic = "fusion/points";

struct PointsQos {
  // Sensor data (best effort, keep last `depth`) by default. Reliable writers keep all and
  // block when readers fall behind, so nothing is lost (replays, tests).
  bool reliable = false;
  std::int32_t depth = 8;
};

// Conversions between the wire type and the recorded one (field for field). The DDS sample
// borrows `storage` for its sequences, so `storage` must outlive `sample`'s use.
struct DdsCloudStorage {
  std::string sensor_id;
  std::vector<float> xyz;
  std::vector<std::uint8_t> beyond_range;
};
void ToDds(const fusion::v1::RecordedCloud& cloud, DdsCloudStorage* storage,
           fusion_dds_PointCloud* sample);
void FromDds(const fusion_dds_PointCloud& sample, fusion::v1::RecordedCloud* cloud);

class PointCloudWriter {
 public:
  static Status Create(std::uint32_t domain_id, const std::string& topic, const PointsQos& qos,
                       std::unique_ptr<PointCloudWriter>* out);
  ~PointCloudWriter();
  PointCloudWriter(const PointCloudWriter&) = delete;
  PointCloudWriter& operator=(const PointCloudWriter&) = delete;

  // Waits until at least `count` readers are matched; false on timeout.
  [[nodiscard]] bool WaitForReaders(std::uint32_t count, std::chrono::milliseconds timeout);
  [[nodiscard]] std::uint32_t matched_readers() const;
  Status Write(const fusion::v1::RecordedCloud& cloud);
  // Reliable only: waits until every matched reader acknowledged what was written.
  Status WaitForAcks(std::chrono::milliseconds timeout);

 private:
  PointCloudWriter() = default;
  dds_entity_t participant_ = 0;
  dds_entity_t writer_ = 0;
  DdsCloudStorage storage_;
};

class PointCloudReader {
 public:
  static Status Create(std::uint32_t domain_id, const std::string& topic, const PointsQos& qos,
                       std::unique_ptr<PointCloudReader>* out);
  ~PointCloudReader();
  PointCloudReader(const PointCloudReader&) = delete;
  PointCloudReader& operator=(const PointCloudReader&) = delete;

  // Waits up to `timeout` for data, then takes what arrived (possibly nothing) and appends
  // it to *clouds, with receive_time_unix_ns set to now.
  Status Take(std::chrono::milliseconds timeout, std::vector<fusion::v1::RecordedCloud>* clouds);

 private:
  PointCloudReader() = default;
  dds_entity_t participant_ = 0;
  dds_entity_t reader_ = 0;
  dds_entity_t waitset_ = 0;
};

// Nanoseconds since the Unix epoch, wall clock.
std::int64_t UnixNowNs();

}  // namespace fusion::clients
