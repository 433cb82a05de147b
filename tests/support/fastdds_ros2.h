// Test helper: a Fast DDS participant (ROS 2's default middleware) that publishes ROS 2 messages
// as a ROS 2 node would: topic rt/<name>, type names pkg::msg::dds_::Name_, XCDR1, ROS 2's QoS.
// It stays on loopback (PLATFORM.md): no builtin transports, UDPv4 on 127.0.0.1 only, unicast
// discovery to the well-known ports of the first participants of the domain, no multicast.
// Types: fastddsgen's from idl/ros2/ (tests/support/ros2_fastdds.cmake).
#pragma once

#include <fastdds/rtps/transport/UDPv4TransportDescriptor.h>
#include <fastrtps/utils/IPLocator.h>

#include <chrono>
#include <cmath>
#include <fastdds/dds/domain/DomainParticipant.hpp>
#include <fastdds/dds/domain/DomainParticipantFactory.hpp>
#include <fastdds/dds/publisher/DataWriter.hpp>
#include <fastdds/dds/publisher/Publisher.hpp>
#include <fastdds/dds/publisher/qos/DataWriterQos.hpp>
#include <fastdds/dds/topic/Topic.hpp>
#include <fastdds/dds/topic/TypeSupport.hpp>
#include <map>
#include <memory>
#include <string>
#include <thread>

#include "sensor_msgsPubSubTypes.h"
#include "tf2_msgsPubSubTypes.h"

namespace fusion::testing {

namespace fdds = eprosima::fastdds::dds;

// ROS 2's QoS profiles.
enum class Ros2Qos {
  kSensorData,  // best effort, keep last 5, volatile
  kReliable,    // reliable, keep last 10, volatile (ROS 2's default profile)
  kTf,          // reliable, keep last 100, volatile
  kTfStatic,    // reliable, keep last 1, transient local
};

inline builtin_interfaces::msg::dds_::Time_ Ros2Time(double stamp_s) {
  builtin_interfaces::msg::dds_::Time_ t;
  const double sec = std::floor(stamp_s);
  t.sec(static_cast<std::int32_t>(sec));
  t.nanosec(static_cast<std::uint32_t>(std::lround((stamp_s - sec) * 1e9)));
  return t;
}

class FastDdsRos2 {
 public:
  // `participant_index` picks the well-known ports (7400 + 250 domain + 10 + 2 index); the
  // initial peers are indices 0..3, where fusiond's Cyclone participant sits.
  FastDdsRos2(unsigned domain, int participant_index = 30) {
    namespace rtps = eprosima::fastrtps::rtps;
    fdds::DomainParticipantQos qos;
    qos.name("fusion_ros2_test");
    qos.transport().use_builtin_transports = false;
    auto udp = std::make_shared<eprosima::fastdds::rtps::UDPv4TransportDescriptor>();
    udp->interfaceWhiteList.emplace_back("127.0.0.1");
    qos.transport().user_transports.push_back(udp);
    const std::uint32_t base = 7400 + 250 * domain;
    auto locator = [](std::uint32_t port) {
      rtps::Locator_t l;
      l.kind = LOCATOR_KIND_UDPv4;
      rtps::IPLocator::setIPv4(l, 127, 0, 0, 1);
      l.port = port;
      return l;
    };
    auto& builtin = qos.wire_protocol().builtin;
    // A metatraffic unicast locator of our own: no default multicast locators.
    builtin.metatrafficUnicastLocatorList.push_back(locator(base + 10 + 2 * participant_index));
    qos.wire_protocol().default_unicast_locator_list.push_back(
        locator(base + 11 + 2 * participant_index));
    for (std::uint32_t i = 0; i < 4; ++i) {
      builtin.initialPeersList.push_back(locator(base + 10 + 2 * i));
    }
    builtin.discovery_config.leaseDuration_announcementperiod =
        eprosima::fastrtps::Duration_t(0, 250'000'000);
    qos.wire_protocol().participant_id = participant_index;
    participant_ = fdds::DomainParticipantFactory::get_instance()->create_participant(domain, qos);
    if (participant_ != nullptr) {
      publisher_ = participant_->create_publisher(fdds::PUBLISHER_QOS_DEFAULT);
    }
  }
  ~FastDdsRos2() {
    if (participant_ == nullptr) return;
    participant_->delete_contained_entities();
    fdds::DomainParticipantFactory::get_instance()->delete_participant(participant_);
  }
  FastDdsRos2(const FastDdsRos2&) = delete;
  FastDdsRos2& operator=(const FastDdsRos2&) = delete;

  [[nodiscard]] bool ok() const { return publisher_ != nullptr; }

  // A writer of `PubSubType` on `topic` (created once per topic).
  template <class PubSubType>
  fdds::DataWriter* Writer(const std::string& topic, Ros2Qos profile) {
    if (auto it = writers_.find(topic); it != writers_.end()) return it->second;
    fdds::TypeSupport type(new PubSubType());
    if (type.register_type(participant_) != ReturnCode_t::RETCODE_OK) return nullptr;
    fdds::Topic* t =
        participant_->create_topic(topic, type.get_type_name(), fdds::TOPIC_QOS_DEFAULT);
    if (t == nullptr) return nullptr;
    fdds::DataWriterQos qos = fdds::DATAWRITER_QOS_DEFAULT;
    const bool reliable = profile != Ros2Qos::kSensorData;
    qos.reliability().kind =
        reliable ? fdds::RELIABLE_RELIABILITY_QOS : fdds::BEST_EFFORT_RELIABILITY_QOS;
    qos.history().kind = fdds::KEEP_LAST_HISTORY_QOS;
    qos.history().depth = profile == Ros2Qos::kSensorData ? 5
                          : profile == Ros2Qos::kReliable ? 10
                          : profile == Ros2Qos::kTf       ? 100
                                                          : 1;
    qos.durability().kind = profile == Ros2Qos::kTfStatic ? fdds::TRANSIENT_LOCAL_DURABILITY_QOS
                                                          : fdds::VOLATILE_DURABILITY_QOS;
    // Readers acknowledge on heartbeats: Fast DDS's default period (3 s) would make every
    // acknowledged write take seconds.
    qos.reliable_writer_qos().times.heartbeatPeriod = eprosima::fastrtps::Duration_t(0, 20'000'000);
    fdds::DataWriter* writer = publisher_->create_datawriter(t, qos);
    writers_[topic] = writer;
    return writer;
  }

  // Waits until `writer` matched a reader (fusiond's).
  static bool WaitForReader(fdds::DataWriter* writer, std::chrono::milliseconds timeout) {
    const auto end = std::chrono::steady_clock::now() + timeout;
    while (std::chrono::steady_clock::now() < end) {
      fdds::PublicationMatchedStatus status;
      if (writer->get_publication_matched_status(status) == ReturnCode_t::RETCODE_OK &&
          status.current_count > 0) {
        return true;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    return false;
  }

  // Writes and, for a reliable writer, waits until the readers acknowledged the sample.
  template <class Message>
  static bool Publish(fdds::DataWriter* writer, Message& message) {
    if (writer == nullptr || !writer->write(&message)) return false;
    if (writer->get_qos().reliability().kind != fdds::RELIABLE_RELIABILITY_QOS) return true;
    return writer->wait_for_acknowledgments(eprosima::fastrtps::Duration_t(5, 0)) ==
           ReturnCode_t::RETCODE_OK;
  }

 private:
  fdds::DomainParticipant* participant_ = nullptr;
  fdds::Publisher* publisher_ = nullptr;
  std::map<std::string, fdds::DataWriter*> writers_;
};

}  // namespace fusion::testing
