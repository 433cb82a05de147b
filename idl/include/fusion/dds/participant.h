// The one place that joins the DDS bus: fusiond, the client tools and the tests all create
// their participants here, with the embedded configuration that keeps traffic on loopback
// unless CYCLONEDDS_URI names another one.
#pragma once

#include <dds/dds.h>

#include <cstdint>
#include <string>

namespace fusion::dds {

// Cyclone DDS configuration that stays on 127.0.0.1 without multicast, with fragment and
// socket-buffer sizes that carry multi-megabyte clouds and a bound on the samples reassembled
// from fragments at once (see PLATFORM.md).
extern const char* const kLoopbackDdsConfig;

// Creates the domain with kLoopbackDdsConfig unless the environment sets CYCLONEDDS_URI,
// then a participant in it. Returns the participant or a negative DDS return code; *error
// (may be null) receives a message naming the failing call.
dds_entity_t CreateParticipant(std::uint32_t domain_id, std::string* error);

}  // namespace fusion::dds
