#include "fusion/clients/dds_io.h"

#include "fusion/dds/participant.h"

#include <cstdlib>
#include <cstring>
#include <thread>

namespace fusion::clients {
namespace {

static_assert(sizeof(float) == 4, "xyz_f32le stores IEEE float32");

bool LittleEndian() {
  const std::uint16_t one = 1;
  unsigned char first = 0;
  std::memcpy(&first, &one, 1);
  return first == 1;
}

Status DdsError(const char* call, dds_return_t rc) {
  return Status::Error(std::string(call) + ": " + dds_strretcode(rc));
}

dds_qos_t* MakeQos(const PointsQos& qos) {
  dds_qos_t* q = dds_create_qos();
  if (qos.reliable) {
    dds_qset_reliability(q, DDS_RELIABILITY_RELIABLE, DDS_SECS(10));
    dds_qset_history(q, DDS_HISTORY_KEEP_ALL, 0);
  } else {
    dds_qset_reliability(q, DDS_RELIABILITY_BEST_EFFORT, 0);
    dds_qset_history(q, DDS_HISTORY_KEEP_LAST, qos.depth > 0 ? qos.depth : 1);
  }
  dds_qset_durability(q, DDS_DURABILITY_VOLATILE);
  return q;
}

// Participant + topic; on failure deletes what it created.
Status CreateTopic(std::uint32_t domain_id, const std::string& topic_name,
                   dds_entity_t* participant, dds_entity_t* topic) {
  std::string error;
  *participant = fusion::dds::CreateParticipant(domain_id, &error);
  if (*participant < 0) return Status::Error(error);
  *topic = dds_create_topic(*participant, &fusion_dds_PointCloud_desc, topic_name.c_str(), nullptr,
                            nullptr);
  if (*topic < 0) {
    const Status s = DdsError("dds_create_topic", *topic);
    dds_delete(*participant);
    return s;
  }
  return Status::Ok();
}

}  // namespace

std::int64_t UnixNowNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

void ToDds(const fusion::v1::RecordedCloud& cloud, DdsCloudStorage* storage,
           fusion_dds_PointCloud* sample) {
  storage->sensor_id = cloud.sensor_id();
  const std::string& bytes = cloud.xyz_f32le();
  storage->xyz.resize(bytes.size() / 4);
  if (LittleEndian()) {
    std::memcpy(storage->xyz.data(), bytes.data(), storage->xyz.size() * 4);
  } else {
    for (std::size_t i = 0; i < storage->xyz.size(); ++i) {
      std::uint32_t v = 0;
      for (int b = 0; b < 4; ++b) v |= std::uint32_t(std::uint8_t(bytes[4 * i + b])) << (8 * b);
      std::memcpy(&storage->xyz[i], &v, 4);
    }
  }
  storage->beyond_range.assign(cloud.beyond_range().begin(), cloud.beyond_range().end());

  *sample = fusion_dds_PointCloud{};
  sample->sensor_id = storage->sensor_id.data();
  sample->sequence_number = cloud.sequence_number();
  sample->stamp.sec = cloud.stamp().sec();
  sample->stamp.nanosec = cloud.stamp().nanosec();
  const auto& pose = cloud.t_world_sensor();
  sample->T_world_sensor = {pose.tx(), pose.ty(), pose.tz(), pose.qx(),
                            pose.qy(), pose.qz(), pose.qw()};
  sample->width = cloud.width();
  sample->height = cloud.height();
  sample->xyz._buffer = storage->xyz.data();
  sample->xyz._length = sample->xyz._maximum = static_cast<uint32_t>(storage->xyz.size());
  sample->xyz._release = false;
  sample->beyond_range._buffer = storage->beyond_range.data();
  sample->beyond_range._length = sample->beyond_range._maximum =
      static_cast<uint32_t>(storage->beyond_range.size());
  sample->beyond_range._release = false;
}

void FromDds(const fusion_dds_PointCloud& sample, fusion::v1::RecordedCloud* cloud) {
  cloud->Clear();
  cloud->set_sensor_id(sample.sensor_id != nullptr ? sample.sensor_id : "");
  cloud->set_sequence_number(sample.sequence_number);
  cloud->mutable_stamp()->set_sec(sample.stamp.sec);
  cloud->mutable_stamp()->set_nanosec(sample.stamp.nanosec);
  auto* pose = cloud->mutable_t_world_sensor();
  pose->set_tx(sample.T_world_sensor.tx);
  pose->set_ty(sample.T_world_sensor.ty);
  pose->set_tz(sample.T_world_sensor.tz);
  pose->set_qx(sample.T_world_sensor.qx);
  pose->set_qy(sample.T_world_sensor.qy);
  pose->set_qz(sample.T_world_sensor.qz);
  pose->set_qw(sample.T_world_sensor.qw);
  cloud->set_width(sample.width);
  cloud->set_height(sample.height);
  std::string* xyz = cloud->mutable_xyz_f32le();
  xyz->resize(static_cast<std::size_t>(sample.xyz._length) * 4);
  if (LittleEndian()) {
    if (!xyz->empty()) std::memcpy(xyz->data(), sample.xyz._buffer, xyz->size());
  } else {
    for (std::size_t i = 0; i < sample.xyz._length; ++i) {
      std::uint32_t v = 0;
      std::memcpy(&v, &sample.xyz._buffer[i], 4);
      for (int b = 0; b < 4; ++b) (*xyz)[4 * i + b] = static_cast<char>(v >> (8 * b));
    }
  }
  cloud->set_beyond_range(std::string(reinterpret_cast<const char*>(sample.beyond_range._buffer),
                                      sample.beyond_range._length));
}

// ---------------------------------------------------------------------------------------------

Status PointCloudWriter::Create(std::uint32_t domain_id, const std::string& topic_name,
                                const PointsQos& qos, std::unique_ptr<PointCloudWriter>* out) {
  std::unique_ptr<PointCloudWriter> w(new PointCloudWriter());
  dds_entity_t topic = 0;
  if (Status s = CreateTopic(domain_id, topic_name, &w->participant_, &topic); !s.ok()) {
    w->participant_ = 0;
    return s;
  }
  dds_qos_t* q = MakeQos(qos);
  w->writer_ = dds_create_writer(w->participant_, topic, q, nullptr);
  dds_delete_qos(q);
  if (w->writer_ < 0) return DdsError("dds_create_writer", w->writer_);
  const dds_return_t rc = dds_set_status_mask(w->writer_, DDS_PUBLICATION_MATCHED_STATUS);
  if (rc != DDS_RETCODE_OK) return DdsError("dds_set_status_mask", rc);
  *out = std::move(w);
  return Status::Ok();
}

PointCloudWriter::~PointCloudWriter() {
  if (participant_ > 0) {
    const dds_return_t rc = dds_delete(participant_);
    if (rc != DDS_RETCODE_OK) std::fprintf(stderr, "dds_delete: %s\n", dds_strretcode(rc));
  }
}

std::uint32_t PointCloudWriter::matched_readers() const {
  dds_publication_matched_status_t status{};
  const dds_return_t rc = dds_get_publication_matched_status(writer_, &status);
  return rc == DDS_RETCODE_OK ? status.current_count : 0;
}

bool PointCloudWriter::WaitForReaders(std::uint32_t count, std::chrono::milliseconds timeout) {
  const auto end = std::chrono::steady_clock::now() + timeout;
  while (matched_readers() < count) {
    if (std::chrono::steady_clock::now() >= end) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  return true;
}

Status PointCloudWriter::Write(const fusion::v1::RecordedCloud& cloud) {
  fusion_dds_PointCloud sample;
  ToDds(cloud, &storage_, &sample);
  const dds_return_t rc = dds_write(writer_, &sample);
  if (rc != DDS_RETCODE_OK) return DdsError("dds_write", rc);
  return Status::Ok();
}

Status PointCloudWriter::WaitForAcks(std::chrono::milliseconds timeout) {
  const dds_return_t rc = dds_wait_for_acks(writer_, DDS_MSECS(timeout.count()));
  if (rc != DDS_RETCODE_OK) return DdsError("dds_wait_for_acks", rc);
  return Status::Ok();
}

// ---------------------------------------------------------------------------------------------

Status PointCloudReader::Create(std::uint32_t domain_id, const std::string& topic_name,
                                const PointsQos& qos, std::unique_ptr<PointCloudReader>* out) {
  std::unique_ptr<PointCloudReader> r(new PointCloudReader());
  dds_entity_t topic = 0;
  if (Status s = CreateTopic(domain_id, topic_name, &r->participant_, &topic); !s.ok()) {
    r->participant_ = 0;
    return s;
  }
  dds_qos_t* q = MakeQos(qos);
  r->reader_ = dds_create_reader(r->participant_, topic, q, nullptr);
  dds_delete_qos(q);
  if (r->reader_ < 0) return DdsError("dds_create_reader", r->reader_);
  const dds_entity_t condition = dds_create_readcondition(r->reader_, DDS_ANY_STATE);
  if (condition < 0) return DdsError("dds_create_readcondition", condition);
  r->waitset_ = dds_create_waitset(r->participant_);
  if (r->waitset_ < 0) return DdsError("dds_create_waitset", r->waitset_);
  const dds_return_t rc = dds_waitset_attach(r->waitset_, condition, r->reader_);
  if (rc != DDS_RETCODE_OK) return DdsError("dds_waitset_attach", rc);
  *out = std::move(r);
  return Status::Ok();
}

PointCloudReader::~PointCloudReader() {
  if (participant_ > 0) {
    const dds_return_t rc = dds_delete(participant_);
    if (rc != DDS_RETCODE_OK) std::fprintf(stderr, "dds_delete: %s\n", dds_strretcode(rc));
  }
}

Status PointCloudReader::Take(std::chrono::milliseconds timeout,
                              std::vector<fusion::v1::RecordedCloud>* clouds) {
  const dds_return_t woken = dds_waitset_wait(waitset_, nullptr, 0, DDS_MSECS(timeout.count()));
  if (woken < 0) return DdsError("dds_waitset_wait", woken);
  constexpr int kBatch = 16;
  for (;;) {
    void* samples[kBatch] = {nullptr};
    dds_sample_info_t infos[kBatch];
    const dds_return_t n = dds_take(reader_, samples, infos, kBatch, kBatch);
    if (n < 0) return DdsError("dds_take", n);
    const std::int64_t now_ns = UnixNowNs();
    for (int i = 0; i < n; ++i) {
      if (!infos[i].valid_data) continue;  // instance state changes (writer gone)
      fusion::v1::RecordedCloud cloud;
      FromDds(*static_cast<const fusion_dds_PointCloud*>(samples[i]), &cloud);
      cloud.set_receive_time_unix_ns(now_ns);
      clouds->push_back(std::move(cloud));
    }
    if (n > 0) {
      const dds_return_t rc = dds_return_loan(reader_, samples, n);
      if (rc != DDS_RETCODE_OK) return DdsError("dds_return_loan", rc);
    }
    if (n < kBatch) return Status::Ok();
  }
}

}  // namespace fusion::clients
