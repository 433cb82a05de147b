// The DDS domain fusiond and its tools join: created with an embedded configuration that
// keeps traffic on loopback unless CYCLONEDDS_URI names another one.
#pragma once

#include <dds/dds.h>

#include <cstdint>
#include <string>

namespace fusion::service {

// Cyclone DDS configuration that stays on 127.0.0.1, without multicast, with fragment and
// socket-buffer sizes that carry multi-megabyte clouds (see PLATFORM.md).
extern const char* const kLoopbackDdsConfig;

// Creates the domain with kLoopbackDdsConfig unless the environment sets CYCLONEDDS_URI,
// then a participant in it. Returns the participant or a negative DDS return code.
// *error receives a message naming the failing call.
dds_entity_t CreateParticipant(std::uint32_t domain_id, std::string* error);

}  // namespace fusion::service
