// soak: a gRPC query client looping over a weighted mix of the FusionMap RPCs. Every call is
// timed and recorded; an OK answer that is wrong (a map version going backwards, a result
// count that does not match, a torn snapshot...) is recorded as BAD_REPLY.
#pragma once

#include <grpcpp/grpcpp.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <memory>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "fusion/v1/map_service.grpc.pb.h"
#include "soak_options.h"
#include "soak_recorder.h"
#include "soak_sensors.h"

namespace fusion::soak {

namespace v1 = fusion::v1;
using std::chrono::milliseconds;

// A channel with a connection of its own (channels to one address share one otherwise).
inline std::shared_ptr<grpc::Channel> NewChannel(const std::string& address) {
  grpc::ChannelArguments args;
  args.SetInt(GRPC_ARG_USE_LOCAL_SUBCHANNEL_POOL, 1);
  return grpc::CreateCustomChannel(address, grpc::InsecureChannelCredentials(), args);
}

// A job due every every_s seconds (0: never), taken by whichever client asks first.
class Schedule {
 public:
  explicit Schedule(double every_s)
      : every_(std::chrono::duration_cast<SoakClock::duration>(
            std::chrono::duration<double>(every_s))),
        next_((SoakClock::now() + every_).time_since_epoch().count()) {}
  bool Claim() {
    if (every_.count() <= 0) return false;
    const auto now = SoakClock::now().time_since_epoch().count();
    auto next = next_.load();
    return now >= next && next_.compare_exchange_strong(next, now + every_.count());
  }

 private:
  SoakClock::duration every_;
  std::atomic<SoakClock::rep> next_;
};

struct ClientSetup {
  std::string address;
  double think_ms = 20;
  std::vector<Weighted> mix = kDefaultMix;
  std::vector<std::pair<std::string, std::uint32_t>> sensors;  // id, beams: for InspectBeam
  Schedule* save = nullptr;
  Schedule* reset = nullptr;
};

inline v1::Point P(double x, double y, double z) {
  v1::Point p;
  p.set_x(x);
  p.set_y(y);
  p.set_z(z);
  return p;
}

class QueryClient {
 public:
  QueryClient(const ClientSetup& setup, Recorder* recorder, std::uint64_t seed)
      : setup_(setup),
        stub_(v1::FusionMap::NewStub(NewChannel(setup.address))),
        recorder_(recorder),
        rng_(seed) {}

  void Run(const std::atomic<bool>& stop) {
    const auto think = std::chrono::duration<double, std::milli>(setup_.think_ms);
    while (!stop) {
      Call(Pick());
      std::this_thread::sleep_for(think);
    }
  }

 private:
  Rpc Pick() {
    if (setup_.save != nullptr && setup_.save->Claim()) return Rpc::kSaveMap;
    if (setup_.reset != nullptr && setup_.reset->Claim()) return Rpc::kResetMap;
    int total = 0;
    for (const Weighted& w : setup_.mix) total += w.weight;
    int draw = std::uniform_int_distribution<int>(0, std::max(0, total - 1))(rng_);
    for (const Weighted& w : setup_.mix) {
      if ((draw -= w.weight) < 0) return w.rpc;
    }
    return Rpc::kQueryPoints;
  }

  void Call(Rpc rpc) {
    switch (rpc) {
      case Rpc::kGetStats:
        return GetStats();
      case Rpc::kQueryPoints:
        return QueryPoints();
      case Rpc::kQueryBox:
        return QueryBox();
      case Rpc::kCastRay:
        return CastRay();
      case Rpc::kFindPlanes:
        return FindPlanes();
      case Rpc::kGetSnapshot:
        return GetSnapshot();
      case Rpc::kListSensors:
        return ListSensors();
      case Rpc::kInspectBeam:
        return InspectBeam();
      case Rpc::kResetMap:
        return ResetMap();
      case Rpc::kSaveMap:
        return SaveMap();
      default:
        return;
    }
  }

  // One call with a deadline, timed and recorded (BAD_REPLY when OK but *bad was set).
  template <typename Body>
  bool Timed(Rpc rpc, milliseconds deadline, Body&& body) {
    grpc::ClientContext context;
    context.set_deadline(std::chrono::system_clock::now() + deadline);
    std::string bad;
    const auto t0 = SoakClock::now();
    const grpc::Status status = body(&context, &bad);
    const double latency_ms =
        std::chrono::duration<double, std::milli>(SoakClock::now() - t0).count();
    if (status.ok() && !bad.empty()) {
      recorder_->BadReply(rpc, bad);
      return false;
    }
    recorder_->Record(rpc, status, latency_ms);
    return status.ok();
  }

  // Versions a client sees one call after another never go back.
  void SeeVersion(std::uint64_t version, std::string* bad) {
    if (version < last_version_) {
      *bad = "map_version " + std::to_string(version) + " after " + std::to_string(last_version_);
    }
    last_version_ = std::max(last_version_, version);
  }

  double U(double lo, double hi) { return std::uniform_real_distribution<double>(lo, hi)(rng_); }
  // A point of the volume the sensors see: the board at x = 1.75 m, the floor at z = -0.41 m.
  v1::Point ScenePoint() { return P(U(0.3, 2.3), U(-1.0, 1.0), U(-0.5, 0.8)); }

  void GetStats() {
    Timed(Rpc::kGetStats, milliseconds(5000), [&](grpc::ClientContext* c, std::string* bad) {
      v1::Stats reply;
      const auto status = stub_->GetStats(c, v1::GetStatsRequest(), &reply);
      if (status.ok()) SeeVersion(reply.map_version(), bad);
      return status;
    });
  }

  // 1, 10, 100 or 1000 points of the scene's volume.
  void QueryPoints() {
    static constexpr int kSizes[] = {1, 1, 1, 1, 10, 10, 10, 100, 100, 1000};
    const int n = kSizes[std::uniform_int_distribution<int>(0, 9)(rng_)];
    v1::QueryPointsRequest request;
    for (int i = 0; i < n; ++i) *request.add_points() = ScenePoint();
    Timed(Rpc::kQueryPoints, milliseconds(5000), [&](grpc::ClientContext* c, std::string* bad) {
      v1::QueryPointsResponse reply;
      const auto status = stub_->QueryPoints(c, request, &reply);
      if (status.ok()) SeeVersion(reply.map_version(), bad);
      if (status.ok() && reply.results_size() != n)
        *bad = std::to_string(reply.results_size()) + " results for " + std::to_string(n);
      return status;
    });
  }

  v1::QueryBoxRequest RandomBox() {
    v1::QueryBoxRequest request;
    const v1::Point c = ScenePoint();
    const double half_m = U(0.05, 0.4);
    *request.mutable_min() = P(c.x() - half_m, c.y() - half_m, c.z() - half_m);
    *request.mutable_max() = P(c.x() + half_m, c.y() + half_m, c.z() + half_m);
    const double kind = U(0, 1);
    if (kind < 0.2) request.add_states(v1::VOXEL_STATE_OCCUPIED);
    if (kind > 0.9) {  // every voxel of a small box, unknown ones too
      *request.mutable_max() = P(c.x() + 0.1, c.y() + 0.1, c.z() + 0.1);
      *request.mutable_min() = P(c.x() - 0.1, c.y() - 0.1, c.z() - 0.1);
      for (auto s : {v1::VOXEL_STATE_UNKNOWN, v1::VOXEL_STATE_FREE, v1::VOXEL_STATE_OCCUPIED})
        request.add_states(s);
    }
    request.set_page_size(U(0, 1) < 0.5 ? 0 : 1000);
    return request;
  }

  // A voxel (centre and edge) that lies at least partly in the box.
  static bool Overlaps(const v1::Voxel& v, const v1::QueryBoxRequest& box) {
    const double h = v.size_m() / 2 + 1e-6;
    return v.center().x() + h >= box.min().x() && v.center().x() - h <= box.max().x() &&
           v.center().y() + h >= box.min().y() && v.center().y() - h <= box.max().y() &&
           v.center().z() + h >= box.min().z() && v.center().z() - h <= box.max().z();
  }

  static std::string Text(const v1::Point& p) {
    char text[80];
    std::snprintf(text, sizeof text, "(%.3f, %.3f, %.3f)", p.x(), p.y(), p.z());
    return text;
  }
  static std::string Text(const v1::Voxel& v) {
    return Text(v.center()) + " size " + std::to_string(v.size_m()) + " state " +
           std::to_string(v.state());
  }
  static std::string Text(const v1::QueryBoxRequest& b) {
    std::string states;
    for (const auto s : b.states()) states += std::to_string(s);
    return Text(b.min()) + "-" + Text(b.max()) + " states [" + states + "] page_size " +
           std::to_string(b.page_size()) +
           (b.page_token().empty() ? "" : " token " + b.page_token());
  }

  static std::string CheckPage(const v1::QueryBoxResponse& reply,
                               const v1::QueryBoxRequest& request) {
    if (request.page_size() > 0 && reply.voxels_size() > static_cast<int>(request.page_size()))
      return std::to_string(reply.voxels_size()) + " voxels on a page of " +
             std::to_string(request.page_size());
    for (const auto& v : reply.voxels()) {
      if (!Overlaps(v, request)) return "voxel " + Text(v) + " outside box " + Text(request);
    }
    return {};
  }

  // A box, and up to 3 more pages of it (each page is one call).
  void QueryBox() {
    v1::QueryBoxRequest request = RandomBox();
    for (int page = 0; page < 4; ++page) {
      v1::QueryBoxResponse reply;
      const bool ok =
          Timed(Rpc::kQueryBox, milliseconds(5000), [&](grpc::ClientContext* c, std::string* bad) {
            const auto status = stub_->QueryBox(c, request, &reply);
            if (status.ok()) SeeVersion(reply.map_version(), bad);
            if (status.ok() && bad->empty()) *bad = CheckPage(reply, request);
            return status;
          });
      if (!ok || reply.next_page_token().empty()) return;
      request.set_page_token(reply.next_page_token());
    }
  }

  // From a point of the sensors' lap towards the board, 5 m at most.
  void CastRay() {
    const Eigen::Vector3d o = RigPoseAt(U(0, kLapS)).translation();
    v1::CastRayRequest request;
    *request.mutable_origin() = P(o.x(), o.y(), o.z());
    *request.mutable_direction() = P(1.75 - o.x(), U(-0.8, 0.8) - o.y(), U(-0.5, 0.8) - o.z());
    request.set_max_range_m(5.0);
    request.set_ignore_unknown(U(0, 1) < 0.5);
    Timed(Rpc::kCastRay, milliseconds(5000), [&](grpc::ClientContext* c, std::string* bad) {
      v1::CastRayResponse reply;
      const auto status = stub_->CastRay(c, request, &reply);
      if (status.ok()) SeeVersion(reply.map_version(), bad);
      if (status.ok() && !(reply.range_m() >= 0 && reply.range_m() <= 5.0 + 0.1))
        *bad = "range_m " + std::to_string(reply.range_m()) + " beyond max_range_m 5";
      return status;
    });
  }

  // Planes of the board region or of the whole map.
  void FindPlanes() {
    v1::FindPlanesRequest request;
    if (U(0, 1) < 0.5) {
      *request.mutable_region_min() = P(1.4, -0.9, -0.6);
      *request.mutable_region_max() = P(2.1, 0.9, 0.9);
    }
    request.set_max_planes(8);
    Timed(Rpc::kFindPlanes, milliseconds(20000), [&](grpc::ClientContext* c, std::string* bad) {
      v1::FindPlanesResponse reply;
      const auto status = stub_->FindPlanes(c, request, &reply);
      if (status.ok()) SeeVersion(reply.map_version(), bad);
      for (const auto& p : reply.planes()) {
        const double n = std::hypot(p.normal().x(), p.normal().y(), p.normal().z());
        if (std::abs(n - 1) > 1e-3) *bad = "a plane normal of length " + std::to_string(n);
      }
      if (reply.planes_size() > 8) *bad = std::to_string(reply.planes_size()) + " planes of 8";
      return status;
    });
  }

  // Chunks must follow each other: one version, one total, offsets without gaps.
  static std::string CheckChunks(const std::vector<v1::SnapshotChunk>& chunks) {
    std::uint64_t offset = 0;
    for (const auto& c : chunks) {
      if (c.offset() != offset)
        return "chunk at offset " + std::to_string(c.offset()) + ", expected " +
               std::to_string(offset);
      if (c.total_bytes() != chunks.front().total_bytes() ||
          c.map_version() != chunks.front().map_version())
        return "chunks of different snapshots";
      offset += c.data().size();
    }
    if (chunks.empty() || offset != chunks.front().total_bytes()) return "snapshot incomplete";
    return {};
  }

  void GetSnapshot() {
    v1::GetSnapshotRequest request;
    request.set_format(U(0, 1) < 0.5 ? v1::GetSnapshotRequest::FORMAT_BT
                                     : v1::GetSnapshotRequest::FORMAT_OT);
    Timed(Rpc::kGetSnapshot, milliseconds(20000), [&](grpc::ClientContext* c, std::string* bad) {
      auto reader = stub_->GetSnapshot(c, request);
      std::vector<v1::SnapshotChunk> chunks(1);
      while (reader->Read(&chunks.back())) chunks.emplace_back();
      chunks.pop_back();
      const auto status = reader->Finish();
      if (status.ok()) *bad = CheckChunks(chunks);
      if (status.ok() && bad->empty()) SeeVersion(chunks.front().map_version(), bad);
      return status;
    });
  }

  void ListSensors() {
    Timed(Rpc::kListSensors, milliseconds(5000), [&](grpc::ClientContext* c, std::string* bad) {
      v1::ListSensorsResponse reply;
      const auto status = stub_->ListSensors(c, v1::ListSensorsRequest(), &reply);
      for (const auto& [id, beams] : setup_.sensors) {
        bool listed = false;
        for (const auto& s : reply.sensors()) listed = listed || s.id() == id;
        if (status.ok() && !listed) *bad = "sensor " + id + " not listed";
      }
      return status;
    });
  }

  void InspectBeam() {
    if (setup_.sensors.empty()) return;
    const auto& [id, beams] = setup_.sensors[rng_() % setup_.sensors.size()];
    v1::InspectBeamRequest request;
    request.set_sensor_id(id);
    request.set_beam(static_cast<std::uint32_t>(rng_() % std::max<std::uint32_t>(1, beams)));
    Timed(Rpc::kInspectBeam, milliseconds(5000), [&](grpc::ClientContext* c, std::string* bad) {
      v1::InspectBeamResponse reply;
      const auto status = stub_->InspectBeam(c, request, &reply);
      if (status.ok() && reply.cell_occupancy_size() > 0 &&
          reply.first_hit_size() != reply.cell_occupancy_size() + 1)
        *bad = std::to_string(reply.first_hit_size()) + " first-hit masses for " +
               std::to_string(reply.cell_occupancy_size()) + " cells";
      return status;
    });
  }

  void ResetMap() {
    Timed(Rpc::kResetMap, milliseconds(20000), [&](grpc::ClientContext* c, std::string* bad) {
      v1::ResetMapResponse reply;
      const auto status = stub_->ResetMap(c, v1::ResetMapRequest(), &reply);
      if (status.ok()) SeeVersion(reply.map_version(), bad);
      return status;
    });
  }

  void SaveMap() {
    Timed(Rpc::kSaveMap, milliseconds(20000), [&](grpc::ClientContext* c, std::string* bad) {
      v1::SaveMapResponse reply;
      const auto status = stub_->SaveMap(c, v1::SaveMapRequest(), &reply);
      if (status.ok() && reply.bytes() == 0) *bad = "SaveMap wrote 0 bytes";
      return status;
    });
  }

  ClientSetup setup_;
  std::unique_ptr<v1::FusionMap::Stub> stub_;
  Recorder* recorder_;
  std::mt19937_64 rng_;
  std::uint64_t last_version_ = 0;
};

}  // namespace fusion::soak
