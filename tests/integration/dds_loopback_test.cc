// A point cloud published by one process is received by another, over loopback, in a
// private DDS domain, with the embedded configuration fusiond uses.
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstring>
#include <string>
#include <thread>

#include <gtest/gtest.h>

#include "../support/subprocess.h"
#include "fusion/dds/participant.h"
#include "fusion_dds.h"

namespace {

using fusion::dds::CreateParticipant;

constexpr const char* kTopic = "fusion/points";

dds_qos_t* ReliableQos() {
  dds_qos_t* qos = dds_create_qos();
  dds_qset_reliability(qos, DDS_RELIABILITY_RELIABLE, DDS_SECS(1));
  dds_qset_history(qos, DDS_HISTORY_KEEP_LAST, 1);
  return qos;
}

// Child process: publish one cloud once a reader is matched, then exit 0.
int PublishOne(unsigned domain) {
  std::string error;
  const dds_entity_t participant = CreateParticipant(domain, &error);
  if (participant < 0) return 10;
  const dds_entity_t topic =
      dds_create_topic(participant, &fusion_dds_PointCloud_desc, kTopic, nullptr, nullptr);
  if (topic < 0) return 11;
  dds_qos_t* qos = ReliableQos();
  const dds_entity_t writer = dds_create_writer(participant, topic, qos, nullptr);
  dds_delete_qos(qos);
  if (writer < 0) return 12;
  dds_publication_matched_status_t matched{};
  for (int i = 0; i < 1000 && matched.current_count == 0; ++i) {
    dds_get_publication_matched_status(writer, &matched);
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  if (matched.current_count == 0) return 13;

  float xyz[6] = {0.f, 0.f, 1.75f, NAN, NAN, NAN};
  uint8_t beyond[2] = {0, 1};
  fusion_dds_PointCloud cloud{};
  cloud.sensor_id = const_cast<char*>("sr3000");
  cloud.sequence_number = 7;
  cloud.T_world_sensor.qw = 1.0;
  cloud.width = 2;
  cloud.height = 1;
  cloud.xyz._buffer = xyz;
  cloud.xyz._length = cloud.xyz._maximum = 6;
  cloud.beyond_range._buffer = beyond;
  cloud.beyond_range._length = cloud.beyond_range._maximum = 2;
  if (dds_write(writer, &cloud) != DDS_RETCODE_OK) return 14;
  if (dds_wait_for_acks(writer, DDS_SECS(5)) != DDS_RETCODE_OK) return 15;
  dds_delete(participant);
  return 0;
}

TEST(DdsLoopbackTest, CloudCrossesProcessesOnLoopback) {
  const unsigned domain = fusion::testing::PrivateDomainId();
  const pid_t child = fork();
  ASSERT_GE(child, 0);
  if (child == 0) _exit(PublishOne(domain));

  std::string error;
  const dds_entity_t participant = CreateParticipant(domain, &error);
  ASSERT_GT(participant, 0) << error;
  const dds_entity_t topic =
      dds_create_topic(participant, &fusion_dds_PointCloud_desc, kTopic, nullptr, nullptr);
  ASSERT_GT(topic, 0) << dds_strretcode(topic);
  dds_qos_t* qos = ReliableQos();
  const dds_entity_t reader = dds_create_reader(participant, topic, qos, nullptr);
  dds_delete_qos(qos);
  ASSERT_GT(reader, 0) << dds_strretcode(reader);

  void* samples[1] = {nullptr};
  dds_sample_info_t infos[1];
  int taken = 0;
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(20);
  while (taken == 0 && std::chrono::steady_clock::now() < deadline) {
    taken = dds_take(reader, samples, infos, 1, 1);
    ASSERT_GE(taken, 0) << dds_strretcode(taken);
    if (taken == 0) std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  ASSERT_EQ(taken, 1) << "no sample arrived within 20 s";
  ASSERT_TRUE(infos[0].valid_data);
  const auto* cloud = static_cast<const fusion_dds_PointCloud*>(samples[0]);
  EXPECT_STREQ(cloud->sensor_id, "sr3000");
  EXPECT_EQ(cloud->sequence_number, 7u);
  EXPECT_EQ(cloud->width, 2u);
  ASSERT_EQ(cloud->xyz._length, 6u);
  EXPECT_FLOAT_EQ(cloud->xyz._buffer[2], 1.75f);
  EXPECT_TRUE(std::isnan(cloud->xyz._buffer[3]));
  ASSERT_EQ(cloud->beyond_range._length, 2u);
  EXPECT_EQ(cloud->beyond_range._buffer[1], 1);
  dds_return_loan(reader, samples, taken);

  int status = 0;
  ASSERT_EQ(waitpid(child, &status, 0), child);
  EXPECT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 0) << "publisher failed (10+: see PublishOne)";
  dds_delete(participant);
}

}  // namespace
