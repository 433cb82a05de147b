// The server-streaming RPCs' writers (GetSnapshot, StreamUpdates) and the writer that only
// finishes with an error. Internal to service/src: map_service.cc creates them.
#pragma once

#include <grpcpp/grpcpp.h>

#include <cstdint>

#include "fusion/service/map_service.h"

namespace fusion::service {

// Serializes the current map on the heavy-query pool, then streams it in chunks as the client
// reads them; `slot` is held until the stream ends (one copy of the map per slot).
grpc::ServerWriteReactor<fusion::v1::SnapshotChunk>* NewSnapshotWriter(
    ServiceState* state, fusion::v1::GetSnapshotRequest::Format format, CountedSlot slot);

// The voxels changed since `since` (the whole map, page by page, for 0 or when the change log
// no longer reaches back), then one batch per new version; `slot` is held until it ends.
grpc::ServerWriteReactor<fusion::v1::MapUpdate>* NewUpdateWriter(ServiceState* state,
                                                                 std::uint64_t since,
                                                                 bool versions_only,
                                                                 CountedSlot slot);

template <typename Message>
class ErrorWriter final : public grpc::ServerWriteReactor<Message> {
 public:
  explicit ErrorWriter(const grpc::Status& status) { this->Finish(status); }
  void OnDone() override { delete this; }
};

}  // namespace fusion::service
