#include "map_streams.h"

#include <deque>
#include <memory>
#include <mutex>
#include <optional>

#include "fusion/core/octree_merge.h"
#include "fusion/service/persistence.h"

namespace fusion::service {
namespace {

using grpc::Status;
using grpc::StatusCode;

class SnapshotWriter final : public grpc::ServerWriteReactor<fusion::v1::SnapshotChunk> {
 public:
  // Serializes the current map on the query pool, then streams it in chunks. The slot (one of
  // limits.max_heavy_queries) is held until the stream ends: one copy of the map per slot.
  SnapshotWriter(ServiceState* state, fusion::v1::GetSnapshotRequest::Format format,
                 CountedSlot slot)
      : chunk_bytes_(state->config.limits().snapshot_chunk_bytes()), slot_(std::move(slot)) {
    state->heavy_pool->Post([this, state, format] {
      try {
        const auto snapshot = state->hub->Current();
        data_ = format == fusion::v1::GetSnapshotRequest::FORMAT_BT ? SerializeBt(*snapshot->tree, state->thresholds)
                                                                    : SerializeOt(*snapshot->tree);
        version_ = snapshot->version;
      } catch (const std::exception& e) {
        Finish(Status(StatusCode::INTERNAL, std::string("GetSnapshot: ") + e.what()));
        return;
      }
      WriteNext();
    });
  }
  void OnWriteDone(bool ok) override {
    if (!ok) {
      Finish(Status(StatusCode::CANCELLED, "snapshot stream broken"));
      return;
    }
    WriteNext();
  }
  void OnDone() override { delete this; }

 private:
  void WriteNext() {
    if (offset_ >= data_.size()) {
      Finish(Status::OK);
      return;
    }
    const std::size_t n = std::min(chunk_bytes_, data_.size() - offset_);
    chunk_.set_map_version(version_);
    chunk_.set_total_bytes(data_.size());
    chunk_.set_offset(offset_);
    chunk_.set_data(data_.data() + offset_, n);
    offset_ += n;
    StartWrite(&chunk_);
  }

  std::size_t chunk_bytes_;
  CountedSlot slot_;
  std::string data_;
  std::uint64_t version_ = 0;
  std::size_t offset_ = 0;
  fusion::v1::SnapshotChunk chunk_;
};

class UpdateWriter final : public grpc::ServerWriteReactor<fusion::v1::MapUpdate> {
 public:
  // Pages of one incremental batch a subscriber may hold before it gets a full resend instead.
  static constexpr std::size_t kMaxBatchPages = 8;

  UpdateWriter(ServiceState* state, std::uint64_t since, bool versions_only, CountedSlot slot)
      : state_(state),
        slot_(std::move(slot)),
        sent_version_(since),
        full_next_(since == 0),
        versions_only_(versions_only) {
    // Subscribed before taking mutex_: the hub calls OnPublish with its subscriber lock held,
    // and OnPublish takes mutex_ (one lock order). A publish in between waits for started_.
    subscription_ = state_->hub->Subscribe([this] { OnPublish(); });
    std::lock_guard<std::mutex> lock(mutex_);
    PrepareLocked(/*first=*/true);
    started_ = true;
    WriteNextLocked();
  }
  void OnWriteDone(bool ok) override {
    std::lock_guard<std::mutex> lock(mutex_);
    writing_ = false;
    if (!ok) {
      FinishLocked(Status(StatusCode::CANCELLED, "update stream broken"));
      return;
    }
    WriteNextLocked();
  }
  void OnCancel() override {
    std::lock_guard<std::mutex> lock(mutex_);
    if (!writing_) FinishLocked(Status(StatusCode::CANCELLED, "cancelled"));
    cancelled_ = true;
  }
  void OnDone() override {
    state_->hub->Unsubscribe(subscription_);
    delete this;
  }

 private:
  void OnPublish() {
    std::lock_guard<std::mutex> lock(mutex_);
    if (finished_ || cancelled_) return;
    if (started_ && pending_.empty() && !writing_ && !full_it_) {
      PrepareLocked(false);
      WriteNextLocked();
    } else {
      more_ = true;  // picked up when the queued messages are written
    }
  }

  // Builds the messages that bring the client from sent_version_ to the current version.
  void PrepareLocked(bool first) {
    const auto snapshot = state_->hub->Current();
    if (!first && snapshot->version <= sent_version_) return;
    if (versions_only_) {
      pending_.emplace_back();
      pending_.back().set_map_version(snapshot->version);
      pending_.back().set_from_version(sent_version_);
      pending_.back().set_complete(true);
      sent_version_ = snapshot->version;
      return;
    }
    const octomap::OcTree& tree = *snapshot->tree;
    const std::size_t per_message = state_->config.limits().max_voxels_per_page();
    std::vector<MapRegion> regions;
    const bool full = full_next_ || !state_->hub->ChangedSince(sent_version_, &regions);
    const auto new_message = [&] {
      pending_.emplace_back();
      pending_.back().set_map_version(snapshot->version);
      pending_.back().set_from_version(full ? 0 : sent_version_);
      pending_.back().set_full(full);
    };
    if (full) {
      // The whole map, one page at a time as the client takes them (NextFullPageLocked): a
      // subscriber holds one page and the version it reads, never the map as messages.
      full_snapshot_ = snapshot;
      full_it_ = tree.begin_leafs();
      sent_version_ = snapshot->version;
      full_next_ = false;
      NextFullPageLocked();
      return;
    }
    new_message();
    // What each changed region holds now: its leaves, or the region itself (one value, or
    // unknown where the map holds nothing any more). A change larger than kMaxBatchPages pages
    // is sent as a full resend instead, page by page, so that no subscriber buffers much.
    bool too_large = false;
    for (const MapRegion& region : regions) {
      ForEachInRegion(
          tree, region,
          [&](const octomap::OcTreeKey& key, unsigned depth, const octomap::OcTreeNode* node) {
            if (too_large) return;
            if (pending_.back().voxels_size() >= static_cast<int>(per_message)) {
              if (pending_.size() >= kMaxBatchPages) {
                too_large = true;
                return;
              }
              new_message();
            }
            VoxelToProto(tree, key, depth, node, state_->thresholds, pending_.back().add_voxels());
          });
      if (too_large) break;
    }
    if (too_large) {
      pending_.clear();
      full_next_ = true;
      PrepareLocked(/*first=*/true);
      return;
    }
    pending_.back().set_complete(true);
    sent_version_ = snapshot->version;
    full_next_ = false;
  }

  // The next page of a full resend, the last one `complete`.
  void NextFullPageLocked() {
    const octomap::OcTree& tree = *full_snapshot_->tree;
    const int per_message = static_cast<int>(state_->config.limits().max_voxels_per_page());
    pending_.emplace_back();
    fusion::v1::MapUpdate& page = pending_.back();
    page.set_map_version(full_snapshot_->version);
    page.set_from_version(0);
    page.set_full(true);
    for (auto& it = *full_it_; it != tree.end_leafs() && page.voxels_size() < per_message; ++it) {
      VoxelToProto(tree, it.getKey(), it.getDepth(), &*it, state_->thresholds, page.add_voxels());
    }
    if (*full_it_ == tree.end_leafs()) {
      page.set_complete(true);
      full_it_.reset();
      full_snapshot_.reset();
    }
  }

  void WriteNextLocked() {
    if (finished_) return;
    if (cancelled_) {
      FinishLocked(Status(StatusCode::CANCELLED, "cancelled"));
      return;
    }
    if (pending_.empty() && full_it_) NextFullPageLocked();
    if (pending_.empty() && (state_->hub->closed() || state_->shutting_down)) {
      FinishLocked(Status::OK);
      return;
    }
    if (pending_.empty() && more_ && !full_it_) {
      more_ = false;
      PrepareLocked(false);
    }
    if (pending_.empty()) return;
    current_ = std::move(pending_.front());
    pending_.pop_front();
    writing_ = true;
    StartWrite(&current_);
  }

  void FinishLocked(const Status& status) {
    if (finished_) return;
    finished_ = true;
    Finish(status);
  }

  ServiceState* state_;
  CountedSlot slot_;  // one of limits.max_update_streams
  std::mutex mutex_;
  int subscription_ = 0;
  std::uint64_t sent_version_;
  bool full_next_;
  bool versions_only_;
  std::deque<fusion::v1::MapUpdate> pending_;
  fusion::v1::MapUpdate current_;
  // A full resend in progress: the version it reads and where it stands.
  std::shared_ptr<const MapSnapshot> full_snapshot_;
  std::optional<octomap::OcTree::leaf_iterator> full_it_;
  bool started_ = false;  // the first messages are prepared
  bool writing_ = false;
  bool more_ = false;
  bool cancelled_ = false;
  bool finished_ = false;
};

}  // namespace

grpc::ServerWriteReactor<fusion::v1::SnapshotChunk>* NewSnapshotWriter(
    ServiceState* state, fusion::v1::GetSnapshotRequest::Format format, CountedSlot slot) {
  return new SnapshotWriter(state, format, std::move(slot));
}

grpc::ServerWriteReactor<fusion::v1::MapUpdate>* NewUpdateWriter(ServiceState* state,
                                                                 std::uint64_t since,
                                                                 bool versions_only,
                                                                 CountedSlot slot) {
  return new UpdateWriter(state, since, versions_only, std::move(slot));
}

}  // namespace fusion::service
