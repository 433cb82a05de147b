#include "fusion/dds/participant.h"

#include <cstdlib>

namespace fusion::dds {

const char* const kLoopbackDdsConfig =
    R"(<CycloneDDS xmlns="https://cdds.io/config"><Domain id="any">)"
    R"(<General><Interfaces><NetworkInterface address="127.0.0.1"/></Interfaces>)"
    R"(<AllowMulticast>false</AllowMulticast>)"
    R"(<MaxMessageSize>65500B</MaxMessageSize><FragmentSize>65000B</FragmentSize></General>)"
    R"(<Discovery><ParticipantIndex>auto</ParticipantIndex>)"
    R"(<MaxAutoParticipantIndex>50</MaxAutoParticipantIndex>)"
    R"(<Peers><Peer address="127.0.0.1"/></Peers></Discovery>)"
    R"(<Internal><SocketReceiveBufferSize min="4MB"/>)"
    // Samples reassembled at once from fragments: each can be a multi-megabyte cloud.
    R"(<DefragReliableMaxSamples>4</DefragReliableMaxSamples>)"
    R"(<DefragUnreliableMaxSamples>2</DefragUnreliableMaxSamples></Internal>)"
    R"(</Domain></CycloneDDS>)";

dds_entity_t CreateParticipant(std::uint32_t domain_id, std::string* error) {
  const char* uri = std::getenv("CYCLONEDDS_URI");
  if (uri == nullptr || *uri == '\0') {
    const dds_entity_t domain = dds_create_domain(domain_id, kLoopbackDdsConfig);
    // PRECONDITION_NOT_MET: the domain exists already in this process; reuse it.
    if (domain < 0 && domain != DDS_RETCODE_PRECONDITION_NOT_MET) {
      if (error) *error = std::string("dds_create_domain: ") + dds_strretcode(domain);
      return domain;
    }
  }
  const dds_entity_t participant = dds_create_participant(domain_id, nullptr, nullptr);
  if (participant < 0 && error) {
    *error = std::string("dds_create_participant: ") + dds_strretcode(participant);
  }
  return participant;
}

}  // namespace fusion::dds
