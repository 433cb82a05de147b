// DDS ingest: a reader on the point-cloud topic, served by its own thread, that validates every
// sample, counts and logs (rate-limited) the rejected ones and queues the rest.
#pragma once

#include <dds/dds.h>

#include <atomic>
#include <chrono>
#include <string>
#include <thread>

#include "fusion/core/status.h"
#include "fusion/service/ingest_queues.h"
#include "fusion/service/rejection_log.h"
#include "fusion/service/validation.h"

namespace fusion::service {

struct DdsIngestOptions {
  std::string topic = "fusion/points";
  bool reliable = false;  // default: best effort (sensor data)
  IngestLimits limits;
  // The queues' byte bound (IngestQueues): a reliable reader holds as many samples of
  // limits.max_points as fit it (2..64), so DDS holds writers back before memory grows.
  std::size_t max_queued_bytes = 256u << 20;
  // At most one log line per rejection reason per this interval (the rest are counted).
  std::chrono::milliseconds log_interval{1000};
};

class DdsIngest {
 public:
  DdsIngest(IngestQueues* queues, DdsIngestOptions options);
  ~DdsIngest();
  DdsIngest(const DdsIngest&) = delete;
  DdsIngest& operator=(const DdsIngest&) = delete;

  // Creates the topic and reader in `participant` and starts the thread.
  [[nodiscard]] Status Start(dds_entity_t participant);
  // Stops the thread and deletes the reader (the participant stays).
  void Stop();

 private:
  void Loop();
  // The topic filter: false (counted, logged) for a sample whose sensor id is empty or not
  // configured, before the reader keeps an instance for it. Runs on DDS's receive threads.
  static bool AcceptSensor(const void* sample, void* self);
  // The reader's listener: counts the writers matched (MatchedWriters). On DDS's threads.
  static void OnWritersMatched(dds_entity_t reader, dds_subscription_matched_status_t status,
                               void* self);
  void Handle(const fusion_dds_PointCloud& sample);

  IngestQueues* queues_;
  DdsIngestOptions options_;
  dds_entity_t topic_ = 0;
  dds_entity_t reader_ = 0;
  dds_entity_t waitset_ = 0;
  dds_entity_t read_condition_ = 0;
  dds_entity_t stop_condition_ = 0;
  std::atomic<bool> stop_{false};
  std::thread thread_;
  RejectionLog log_;  // used on the ingest thread and DDS's threads (the topic filter)
};

}  // namespace fusion::service
