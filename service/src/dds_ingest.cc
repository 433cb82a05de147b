#include "fusion/service/dds_ingest.h"

#include <spdlog/spdlog.h>

#include <algorithm>

#include "fusion/service/conversions.h"

namespace fusion::service {
namespace {

constexpr int kMaxSamplesPerTake = 16;

// Samples a reliable reader holds before DDS flow control holds the writers back: as many
// clouds of max_points as fit the queues' byte bound, 2..64.
int32_t ReliableReaderSamples(const DdsIngestOptions& options) {
  const std::size_t cloud_bytes = std::size_t{options.limits.max_points} * 13;  // xyz + flag
  const std::size_t fit = options.max_queued_bytes / std::max<std::size_t>(cloud_bytes, 1);
  return static_cast<int32_t>(std::clamp<std::size_t>(fit, 8, 64));
}

std::string DdsError(const char* call, dds_return_t rc) {
  return std::string(call) + ": " + dds_strretcode(rc);
}

}  // namespace

DdsIngest::DdsIngest(IngestQueues* queues, DdsIngestOptions options)
    : queues_(queues), options_(std::move(options)), log_(options_.log_interval) {}

DdsIngest::~DdsIngest() { Stop(); }

Status DdsIngest::Start(dds_entity_t participant) {
  topic_ = dds_create_topic(participant, &fusion_dds_PointCloud_desc, options_.topic.c_str(),
                            nullptr, nullptr);
  if (topic_ < 0) {
    return Status::Error(DdsError("dds_create_topic", topic_));
  }
  if (const dds_return_t rc = dds_set_topic_filter_and_arg(topic_, &DdsIngest::AcceptSensor, this);
      rc != DDS_RETCODE_OK) {
    return Status::Error(DdsError("dds_set_topic_filter_and_arg", rc));
  }
  dds_qos_t* qos = dds_create_qos();
  if (options_.reliable) {
    dds_qset_reliability(qos, DDS_RELIABILITY_RELIABLE, DDS_SECS(1));
  } else {
    dds_qset_reliability(qos, DDS_RELIABILITY_BEST_EFFORT, 0);
  }
  if (options_.reliable) {
    // Lossless: keep every sample; while the queues are full the ingest thread waits, the
    // reader's cache fills up to its limit and DDS flow control holds the writer back.
    dds_qset_history(qos, DDS_HISTORY_KEEP_ALL, 0);
    dds_qset_resource_limits(qos, ReliableReaderSamples(options_), DDS_LENGTH_UNLIMITED,
                             DDS_LENGTH_UNLIMITED);
  } else {
    // Keyed by sensor_id: keep the newest cloud of every sensor (the bounded queues behind
    // this reader do the rest).
    dds_qset_history(qos, DDS_HISTORY_KEEP_LAST, 1);
  }
  dds_qset_durability(qos, DDS_DURABILITY_VOLATILE);
  dds_listener_t* listener = dds_create_listener(this);
  dds_lset_subscription_matched(listener, &DdsIngest::OnWritersMatched);
  reader_ = dds_create_reader(participant, topic_, qos, listener);
  dds_delete_listener(listener);
  dds_delete_qos(qos);
  if (reader_ < 0) {
    return Status::Error(DdsError("dds_create_reader", reader_));
  }
  waitset_ = dds_create_waitset(participant);
  read_condition_ = dds_create_readcondition(reader_, DDS_ANY_STATE);
  stop_condition_ = dds_create_guardcondition(participant);
  for (const auto& [entity, name] : {std::pair{waitset_, "dds_create_waitset"},
                                     std::pair{read_condition_, "dds_create_readcondition"},
                                     std::pair{stop_condition_, "dds_create_guardcondition"}}) {
    if (entity < 0) {
      return Status::Error(DdsError(name, entity));
    }
  }
  dds_return_t rc = dds_waitset_attach(waitset_, read_condition_, 0);
  if (rc == DDS_RETCODE_OK) rc = dds_waitset_attach(waitset_, stop_condition_, 1);
  if (rc != DDS_RETCODE_OK) {
    return Status::Error(DdsError("dds_waitset_attach", rc));
  }
  thread_ = std::thread([this] { Loop(); });
  return Status::Ok();
}

void DdsIngest::Stop() {
  if (thread_.joinable()) {
    stop_ = true;
    dds_set_guardcondition(stop_condition_, true);
    thread_.join();
  }
  for (dds_entity_t* e : {&waitset_, &read_condition_, &stop_condition_, &reader_}) {
    if (*e > 0) dds_delete(*e);
    *e = 0;
  }
}

void DdsIngest::Loop() {
  void* samples[kMaxSamplesPerTake] = {};
  dds_sample_info_t infos[kMaxSamplesPerTake];
  while (!stop_) {
    const dds_return_t woken = dds_waitset_wait(waitset_, nullptr, 0, DDS_MSECS(500));
    if (woken < 0) {
      spdlog::error("dds_waitset_wait: {}", dds_strretcode(woken));
      continue;
    }
    for (;;) {
      const dds_return_t n =
          dds_take(reader_, samples, infos, kMaxSamplesPerTake, kMaxSamplesPerTake);
      if (n < 0) {
        spdlog::error("dds_take: {}", dds_strretcode(n));
        break;
      }
      for (int i = 0; i < n; ++i) {
        if (!infos[i].valid_data) continue;  // dispose / unregister notifications
        try {
          Handle(*static_cast<const fusion_dds_PointCloud*>(samples[i]));
        } catch (const std::exception& e) {
          // Out of memory copying a huge cloud, for instance: drop it, keep serving.
          spdlog::error("ingest: cloud dropped: {}", e.what());
        }
      }
      if (n > 0) dds_return_loan(reader_, samples, n);
      if (n < kMaxSamplesPerTake) break;
    }
  }
}

bool DdsIngest::AcceptSensor(const void* sample, void* self) {
  auto* ingest = static_cast<DdsIngest*>(self);
  const char* id = static_cast<const fusion_dds_PointCloud*>(sample)->sensor_id;
  std::string detail;
  const auto reason = ValidateSensorId(
      id, [ingest](const std::string& s) { return ingest->queues_->Known(s); }, &detail);
  if (!reason) return true;
  const std::string sensor_id = id != nullptr ? id : "";
  ingest->queues_->CountRejected(sensor_id, *reason);
  ingest->log_.Log(*reason, sensor_id, detail);
  return false;
}

void DdsIngest::OnWritersMatched(dds_entity_t, const dds_subscription_matched_status_t status,
                                 void* self) {
  MatchedWriters& matched = static_cast<DdsIngest*>(self)->queues_->matched_writers();
  // Changes, not counts: the ROS 2 readers add theirs to the same count (ros2_ingest.cc).
  matched.current.fetch_add(static_cast<std::uint32_t>(status.current_count_change));
  matched.total.fetch_add(static_cast<std::uint64_t>(status.total_count_change));
  spdlog::info("ingest: {} DDS writer(s) matched ({} since the start)", status.current_count,
               status.total_count);
}

void DdsIngest::Handle(const fusion_dds_PointCloud& sample) {
  std::string detail;
  const auto reason = ValidateSample(
      sample, options_.limits, [this](const std::string& id) { return queues_->Known(id); },
      &detail);
  const std::string sensor_id = sample.sensor_id != nullptr ? sample.sensor_id : "";
  if (reason) {
    queues_->CountRejected(sensor_id, *reason);
    log_.Log(*reason, sensor_id, detail);
    return;
  }
  // Reliable ingest waits for room (lossless); sensor data replaces the oldest cloud.
  Cloud cloud = CloudFromDds(sample);
  cloud.received_at = std::chrono::steady_clock::now();
  (void)queues_->Push(std::move(cloud), options_.reliable ? &stop_ : nullptr);
}

}  // namespace fusion::service
