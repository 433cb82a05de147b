// Test helpers: fusionctl run in-process (fusionctl::Run) with its stdout and stderr captured,
// and a fake fusiond (FusionMap and health services on 127.0.0.1:0) whose answers the tests set
// and which records what it was sent.
#pragma once

#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>
#include <octomap/OcTree.h>

#include <atomic>
#include <chrono>
#include <cstdio>
#include <memory>
#include <mutex>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "fusion/v1/map_service.grpc.pb.h"
#include "fusionctl.h"

namespace fusionctl::testing {

namespace v1 = fusion::v1;

struct RunResult {
  int exit_code = -1;
  std::string out;
  std::string err;
};

// Runs `fusionctl ARGS...` in this process.
inline RunResult RunFusionctl(std::vector<std::string> args) {
  args.insert(args.begin(), "fusionctl");
  std::vector<char*> argv;
  for (auto& a : args) argv.push_back(a.data());
  argv.push_back(nullptr);
  RunResult result;
  ::testing::internal::CaptureStdout();
  ::testing::internal::CaptureStderr();
  result.exit_code = fusionctl::Run(static_cast<int>(args.size()), argv.data());
  std::fflush(nullptr);
  result.out = ::testing::internal::GetCapturedStdout();
  result.err = ::testing::internal::GetCapturedStderr();
  return result;
}

// The lines of `text`, without empty ones.
inline std::vector<std::string> Lines(const std::string& text) {
  std::vector<std::string> lines;
  std::istringstream in(text);
  for (std::string line; std::getline(in, line);) {
    if (!line.empty()) lines.push_back(line);
  }
  return lines;
}

class FakeFusionMap final : public v1::FusionMap::Service {
 public:
  v1::Stats stats;
  std::vector<v1::QueryBoxResponse> box_pages;  // next_page_token set here: "1", "2", ...
  v1::FindPlanesResponse planes;
  grpc::Status points_status = grpc::Status::OK;
  std::chrono::milliseconds ray_delay{0};
  std::atomic<int> calls{0};
  v1::ClearBoxRequest last_clear_box;  // the last ClearBox request (read after the call)

  // The "authorization" metadata of every call so far ("" when absent).
  std::vector<std::string> Authorizations() {
    std::lock_guard<std::mutex> lock(mutex_);
    return authorizations_;
  }

  grpc::Status GetStats(grpc::ServerContext* c, const v1::GetStatsRequest*, v1::Stats* r) override {
    Record(c);
    *r = stats;
    return grpc::Status::OK;
  }
  grpc::Status QueryPoints(grpc::ServerContext* c, const v1::QueryPointsRequest* q,
                           v1::QueryPointsResponse* r) override {
    Record(c);
    if (!points_status.ok()) return points_status;
    r->set_map_version(7);
    for (int i = 0; i < q->points_size(); ++i) r->add_results()->set_probability(0.5);
    return grpc::Status::OK;
  }
  grpc::Status QueryBox(grpc::ServerContext* c, const v1::QueryBoxRequest* q,
                        v1::QueryBoxResponse* r) override {
    Record(c);
    const std::size_t page = q->page_token().empty() ? 0 : std::stoul(q->page_token());
    if (page < box_pages.size()) *r = box_pages[page];
    return grpc::Status::OK;
  }
  grpc::Status CastRay(grpc::ServerContext* c, const v1::CastRayRequest*,
                       v1::CastRayResponse* r) override {
    Record(c);
    std::this_thread::sleep_for(ray_delay);
    r->set_hit(true);
    r->set_range_m(1.5);
    return grpc::Status::OK;
  }
  grpc::Status FindPlanes(grpc::ServerContext* c, const v1::FindPlanesRequest*,
                          v1::FindPlanesResponse* r) override {
    Record(c);
    *r = planes;
    return grpc::Status::OK;
  }
  grpc::Status GetSnapshot(grpc::ServerContext* c, const v1::GetSnapshotRequest*,
                           grpc::ServerWriter<v1::SnapshotChunk>* writer) override {
    Record(c);
    octomap::OcTree tree(0.1);
    tree.updateNode(octomap::point3d(1.0f, 0.0f, 0.0f), true);
    std::ostringstream bytes;
    tree.write(bytes);
    v1::SnapshotChunk chunk;
    chunk.set_map_version(3);
    chunk.set_total_bytes(bytes.str().size());
    chunk.set_data(bytes.str());
    writer->Write(chunk);
    return grpc::Status::OK;
  }
  grpc::Status StreamUpdates(grpc::ServerContext* c, const v1::StreamUpdatesRequest*,
                             grpc::ServerWriter<v1::MapUpdate>* writer) override {
    Record(c);
    for (int version = 1; version <= 2; ++version) {
      v1::MapUpdate update;
      update.set_map_version(version);
      update.set_from_version(version - 1);
      update.set_complete(true);
      update.add_voxels()->set_size_m(0.1);
      writer->Write(update);
    }
    return grpc::Status::OK;
  }
  grpc::Status ListSensors(grpc::ServerContext* c, const v1::ListSensorsRequest*,
                           v1::ListSensorsResponse* r) override {
    Record(c);
    auto* s = r->add_sensors();
    s->set_id("sr");
    s->set_beams(4);
    (*s->mutable_counters()->mutable_rejected_by_reason())["bad_pose"] = 2;
    return grpc::Status::OK;
  }
  grpc::Status InspectBeam(grpc::ServerContext* c, const v1::InspectBeamRequest*,
                           v1::InspectBeamResponse* r) override {
    Record(c);
    r->set_cell_size_m(0.01);
    r->add_cell_occupancy(0.5);
    r->add_first_hit(0.9);
    r->add_first_hit(0.1);
    return grpc::Status::OK;
  }
  grpc::Status ResetMap(grpc::ServerContext* c, const v1::ResetMapRequest*,
                        v1::ResetMapResponse* r) override {
    Record(c);
    r->set_map_version(1);
    return grpc::Status::OK;
  }
  grpc::Status ClearBox(grpc::ServerContext* c, const v1::ClearBoxRequest* q,
                        v1::ClearBoxResponse* r) override {
    Record(c);
    {
      std::lock_guard<std::mutex> lock(mutex_);
      last_clear_box = *q;
    }
    r->set_map_version(2);
    r->set_voxels_cleared(1234);
    return grpc::Status::OK;
  }
  grpc::Status SaveMap(grpc::ServerContext* c, const v1::SaveMapRequest*,
                       v1::SaveMapResponse* r) override {
    Record(c);
    r->set_path("/tmp/map.ot");
    r->set_bytes(10);
    return grpc::Status::OK;
  }

 private:
  void Record(grpc::ServerContext* c) {
    ++calls;
    const auto& metadata = c->client_metadata();
    const auto it = metadata.find("authorization");
    std::lock_guard<std::mutex> lock(mutex_);
    authorizations_.push_back(
        it == metadata.end() ? "" : std::string(it->second.data(), it->second.size()));
  }
  std::mutex mutex_;
  std::vector<std::string> authorizations_;
};

// A fake fusiond on 127.0.0.1:0 for one test.
class FakeFusiondTest : public ::testing::Test {
 protected:
  void SetUp() override {
    grpc::EnableDefaultHealthCheckService(true);
    grpc::ServerBuilder builder;
    int port = 0;
    builder.AddListeningPort("127.0.0.1:0", grpc::InsecureServerCredentials(), &port);
    builder.RegisterService(&service_);
    server_ = builder.BuildAndStart();
    ASSERT_TRUE(server_ && port > 0);
    address_ = "127.0.0.1:" + std::to_string(port);
  }
  void TearDown() override {
    if (server_) server_->Shutdown(std::chrono::system_clock::now() + std::chrono::seconds(2));
  }
  // fusionctl --server <the fake> ARGS...
  RunResult Fusionctl(std::vector<std::string> args) {
    args.insert(args.begin(), {"--server", address_});
    return RunFusionctl(std::move(args));
  }

  FakeFusionMap service_;
  std::unique_ptr<grpc::Server> server_;
  std::string address_;
};

}  // namespace fusionctl::testing
