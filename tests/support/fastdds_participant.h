// Test helper: a Fast DDS participant (eProsima Fast DDS 2.9, ROS 2's default DDS, independent of
// the Cyclone DDS fusiond runs on) that stays on loopback, as PLATFORM.md found works: no builtin
// transports (no shared memory, no default UDP on every interface), one UDPv4 transport on
// 127.0.0.1, no multicast locator, and discovery by unicast to the RTPS well-known ports of the
// first participant indices on 127.0.0.1. Its readers take fastddsgen types
// (tests/support/ros2_fastdds.cmake: "<name>PubSubTypes.h"). The publishing side of ROS 2
// ingest tests is tests/support/fastdds_ros2.h; octomap_msgs read back: fastdds_octomap.h.
#pragma once

#include <fastdds/rtps/transport/UDPv4TransportDescriptor.h>
#include <fastrtps/utils/IPLocator.h>

#include <chrono>
#include <cstdint>
#include <fastdds/dds/domain/DomainParticipant.hpp>
#include <fastdds/dds/domain/DomainParticipantFactory.hpp>
#include <fastdds/dds/subscriber/DataReader.hpp>
#include <fastdds/dds/subscriber/SampleInfo.hpp>
#include <fastdds/dds/subscriber/Subscriber.hpp>
#include <fastdds/dds/subscriber/qos/DataReaderQos.hpp>
#include <fastdds/dds/topic/TypeSupport.hpp>
#include <memory>
#include <string>

namespace fusion::testing {

// RTPS well-known ports (the specification's defaults PB 7400, DG 250, PG 2, d1 10, d3 11): the
// unicast discovery (metatraffic) and user-data ports of participant `index` in `domain`.
inline std::uint32_t RtpsDiscoveryPort(unsigned domain, unsigned index) {
  return 7400 + 250 * domain + 10 + 2 * index;
}
inline std::uint32_t RtpsUserDataPort(unsigned domain, unsigned index) {
  return 7400 + 250 * domain + 11 + 2 * index;
}

inline eprosima::fastrtps::rtps::Locator_t LoopbackLocator(std::uint32_t port) {
  eprosima::fastrtps::rtps::Locator_t locator;
  locator.kind = LOCATOR_KIND_UDPv4;
  eprosima::fastrtps::rtps::IPLocator::setIPv4(locator, "127.0.0.1");
  locator.port = port;
  return locator;
}

// The participant's QoS as index `index` of `domain`, looking for peers at indices
// 0..peer_indices-1 (Cyclone's ParticipantIndex auto hands them out from 0).
inline eprosima::fastdds::dds::DomainParticipantQos LoopbackParticipantQos(
    unsigned domain, unsigned index, const std::string& name, unsigned peer_indices = 20) {
  eprosima::fastdds::dds::DomainParticipantQos qos;
  qos.name(name);
  qos.transport().use_builtin_transports = false;
  auto udp = std::make_shared<eprosima::fastdds::rtps::UDPv4TransportDescriptor>();
  udp->interfaceWhiteList.push_back("127.0.0.1");
  // Maps are megabytes: room for a sample's fragments, as fusiond's Cyclone configuration has.
  udp->receiveBufferSize = 4 << 20;
  udp->sendBufferSize = 4 << 20;
  qos.transport().user_transports.push_back(udp);
  auto& wire = qos.wire_protocol();
  wire.participant_id = static_cast<std::int32_t>(index);
  // Explicit unicast locators: Fast DDS then adds no multicast one (239.255.0.1) of its own.
  wire.builtin.metatrafficUnicastLocatorList.push_back(
      LoopbackLocator(RtpsDiscoveryPort(domain, index)));
  wire.default_unicast_locator_list.push_back(LoopbackLocator(RtpsUserDataPort(domain, index)));
  for (unsigned peer = 0; peer < peer_indices; ++peer) {
    if (peer != index) {
      wire.builtin.initialPeersList.push_back(LoopbackLocator(RtpsDiscoveryPort(domain, peer)));
    }
  }
  return qos;
}

class FastDdsParticipant {
 public:
  // Takes the first free participant index from `first_index` up (the indices below are
  // Cyclone's: fusiond and the test's own publishers). null() when none could be created.
  FastDdsParticipant(unsigned domain, const std::string& name, unsigned first_index = 20) {
    auto* factory = eprosima::fastdds::dds::DomainParticipantFactory::get_instance();
    for (unsigned index = first_index; participant_ == nullptr && index < first_index + 10;
         ++index) {
      participant_ =
          factory->create_participant(domain, LoopbackParticipantQos(domain, index, name));
    }
    if (participant_ != nullptr) {
      subscriber_ = participant_->create_subscriber(eprosima::fastdds::dds::SUBSCRIBER_QOS_DEFAULT);
    }
  }
  // A participant of the XML profile `profile` in `xml_path` (e.g. docker/fastdds-loopback.xml,
  // the profile docs/ros2.md gives ROS 2 nodes), as a ROS 2 node would load it.
  FastDdsParticipant(unsigned domain, const std::string& xml_path, const std::string& profile) {
    auto* factory = eprosima::fastdds::dds::DomainParticipantFactory::get_instance();
    if (factory->load_XML_profiles_file(xml_path) != ReturnCode_t::RETCODE_OK) return;
    participant_ = factory->create_participant_with_profile(domain, profile);
    if (participant_ != nullptr) {
      subscriber_ = participant_->create_subscriber(eprosima::fastdds::dds::SUBSCRIBER_QOS_DEFAULT);
    }
  }
  ~FastDdsParticipant() {
    if (participant_ == nullptr) return;
    participant_->delete_contained_entities();
    eprosima::fastdds::dds::DomainParticipantFactory::get_instance()->delete_participant(
        participant_);
  }
  FastDdsParticipant(const FastDdsParticipant&) = delete;
  FastDdsParticipant& operator=(const FastDdsParticipant&) = delete;

  [[nodiscard]] bool ok() const { return subscriber_ != nullptr; }

  // octomap_server's latched topics: reliable, transient local, keep last 1.
  static eprosima::fastdds::dds::DataReaderQos LatchedReaderQos() {
    eprosima::fastdds::dds::DataReaderQos qos = eprosima::fastdds::dds::DATAREADER_QOS_DEFAULT;
    qos.reliability().kind = eprosima::fastdds::dds::RELIABLE_RELIABILITY_QOS;
    qos.durability().kind = eprosima::fastdds::dds::TRANSIENT_LOCAL_DURABILITY_QOS;
    qos.history().kind = eprosima::fastdds::dds::KEEP_LAST_HISTORY_QOS;
    qos.history().depth = 1;
    // The generated types declare a maximum size of a few hundred bytes (unbounded sequences
    // count as 100 elements): samples of megabytes need payloads that grow.
    qos.endpoint().history_memory_policy =
        eprosima::fastrtps::rtps::PREALLOCATED_WITH_REALLOC_MEMORY_MODE;
    return qos;
  }

  // A reader of `topic` with the fastddsgen type PubSubType (e.g. Octomap_PubSubType); null on
  // failure. The participant owns it.
  template <class PubSubType>
  eprosima::fastdds::dds::DataReader* CreateReader(
      const std::string& topic_name,
      const eprosima::fastdds::dds::DataReaderQos& qos = LatchedReaderQos()) {
    if (!ok()) return nullptr;
    eprosima::fastdds::dds::TypeSupport type(new PubSubType());
    if (type.register_type(participant_) != ReturnCode_t::RETCODE_OK) return nullptr;
    auto* topic = participant_->create_topic(topic_name, type.get_type_name(),
                                             eprosima::fastdds::dds::TOPIC_QOS_DEFAULT);
    return topic == nullptr ? nullptr : subscriber_->create_datareader(topic, qos);
  }

 private:
  eprosima::fastdds::dds::DomainParticipant* participant_ = nullptr;
  eprosima::fastdds::dds::Subscriber* subscriber_ = nullptr;
};

// Takes the next valid sample within `timeout`; false if none came.
template <class T>
bool TakeSample(eprosima::fastdds::dds::DataReader* reader, T* sample,
                std::chrono::milliseconds timeout) {
  const auto end = std::chrono::steady_clock::now() + timeout;
  eprosima::fastdds::dds::SampleInfo info;
  while (true) {
    while (reader->take_next_sample(sample, &info) == ReturnCode_t::RETCODE_OK) {
      if (info.valid_data) return true;
    }
    const auto left = end - std::chrono::steady_clock::now();
    if (left <= std::chrono::milliseconds(0)) return false;
    const double left_s = std::chrono::duration<double>(left).count();
    reader->wait_for_unread_message(eprosima::fastrtps::Duration_t(std::min(left_s, 0.1)));
  }
}

}  // namespace fusion::testing
