// fusiond's persistence end to end: a real fusiond process on 127.0.0.1:0 in a private DDS
// domain (the FusiondServiceTest fixture, tests/support/fusiond_fixture.h), its snapshot file
// restored after kill -9, set aside when corrupt, and its write failures made visible.
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>
#include <octomap/AbstractOcTree.h>
#include <octomap/OcTree.h>
#include <unistd.h>

#include <chrono>
#include <csignal>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <memory>
#include <string>
#include <thread>

#include "../support/fusiond_fixture.h"
#include "fusion/v1/map_service.grpc.pb.h"
#include "grpc/health/v1/health.grpc.pb.h"

namespace {

using namespace fusion::testing;  // NOLINT: the fixture and its helpers
using namespace std::chrono_literals;
namespace v1 = fusion::v1;
namespace fs = std::filesystem;

bool Occupied(const octomap::OcTree& tree, const Eigen::Vector3d& p) {
  const auto* node = tree.search(p.x(), p.y(), p.z());
  return node != nullptr && tree.isNodeOccupied(node);
}

TEST_F(FusiondServiceTest, KillNineRestartRestoresThePeriodicSnapshot) {
  auto fusiond = Start();
  ASSERT_TRUE(fusiond);
  {
    TestPublisher publisher(domain_);
    ASSERT_TRUE(publisher.WaitForReader(10s));
    ASSERT_GT(MapTheBoard(publisher), 0u);
  }
  // Wait for a periodic snapshot (interval 1 s) that holds the board.
  const auto end = std::chrono::steady_clock::now() + 10s;
  bool saved = false;
  while (!saved && std::chrono::steady_clock::now() < end) {
    std::this_thread::sleep_for(200ms);
    std::unique_ptr<octomap::OcTree> tree;
    if (fs::exists(snapshot_)) {
      std::ifstream in(snapshot_, std::ios::binary);
      std::unique_ptr<octomap::AbstractOcTree> read(octomap::AbstractOcTree::read(in));
      auto* octree = dynamic_cast<octomap::OcTree*>(read.get());
      saved = octree != nullptr && Occupied(*octree, kOnBoard);
    }
  }
  ASSERT_TRUE(saved) << "no periodic snapshot with the board in " << snapshot_;
  const pid_t killed = fusiond->pid();
  EXPECT_EQ(fusiond->Stop(SIGKILL, 10s), 128 + SIGKILL);
  // What a kill -9 in the middle of a write leaves: the restart removes it.
  const std::string stale = snapshot_ + ".tmp-" + std::to_string(killed);
  std::ofstream(stale) << "half a snapshot";
  auto restarted = Start();
  ASSERT_TRUE(restarted);
  EXPECT_FALSE(fs::exists(stale)) << "stale temporary file left behind";
  EXPECT_EQ(Occupancy(kOnBoard).state(), v1::VOXEL_STATE_OCCUPIED);
  EXPECT_EQ(restarted->Stop(SIGTERM, 15s), 0);
}

TEST_F(FusiondServiceTest, CorruptSnapshotIsSetAsideAndNotOverwritten) {
  std::ofstream(snapshot_) << "# Octomap OcTree file\nid OcTree\nsize 1000\nres 0.05\ndata\nxyz";
  auto fusiond = Start();
  ASSERT_TRUE(fusiond);
  EXPECT_EQ(Stats().map_leaves(), 0u);
  int corrupt_files = 0;
  for (const auto& entry : fs::directory_iterator(dir_)) {
    if (entry.path().filename().string().rfind("map.ot.corrupt-", 0) == 0) {
      ++corrupt_files;
      std::ifstream in(entry.path());
      std::string first;
      std::getline(in, first);
      EXPECT_EQ(first, "# Octomap OcTree file");  // the original bytes, kept
    }
  }
  EXPECT_EQ(corrupt_files, 1);
  EXPECT_EQ(fusiond->Stop(SIGTERM, 15s), 0);
  EXPECT_TRUE(fs::exists(snapshot_));  // a new, valid snapshot
  std::ifstream in(snapshot_, std::ios::binary);
  std::unique_ptr<octomap::AbstractOcTree> read(octomap::AbstractOcTree::read(in));
  EXPECT_NE(dynamic_cast<octomap::OcTree*>(read.get()), nullptr);
}

// Persistence failures are visible: counted in GetStats, the health entry
// fusion.v1.Persistence NOT_SERVING while writes fail (SERVING again once they succeed), and a
// shutdown that cannot write its final snapshot exits non-zero.
TEST_F(FusiondServiceTest, SnapshotFailuresShowInStatsHealthAndTheExitCode) {
  const std::string missing = dir_ + "/missing";
  {
    std::ifstream in(config_);
    std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    const std::string old_path = "\"" + snapshot_ + "\"";
    text.replace(text.find(old_path), old_path.size(), "\"" + missing + "/map.ot\"");
    std::ofstream(config_) << text;
  }
  auto fusiond = Start();
  ASSERT_TRUE(fusiond);
  const auto persistence = [&] {
    auto health = grpc::health::v1::Health::NewStub(channel_);
    grpc::ClientContext context;
    context.set_deadline(In(5s));
    grpc::health::v1::HealthCheckRequest request;
    request.set_service("fusion.v1.Persistence");
    grpc::health::v1::HealthCheckResponse reply;
    EXPECT_TRUE(health->Check(&context, request, &reply).ok());
    return reply.status();
  };
  const auto wait_for = [&](grpc::health::v1::HealthCheckResponse::ServingStatus status) {
    const auto end = std::chrono::steady_clock::now() + 10s;
    while (persistence() != status && std::chrono::steady_clock::now() < end) {
      std::this_thread::sleep_for(100ms);
    }
    return persistence() == status;
  };
  // The periodic write (every second) fails: its directory does not exist.
  ASSERT_TRUE(wait_for(grpc::health::v1::HealthCheckResponse::NOT_SERVING));
  v1::Stats stats = Stats();
  EXPECT_GE(stats.snapshots_failed(), 1u);
  EXPECT_NE(stats.last_snapshot_error().find(missing), std::string::npos)
      << stats.last_snapshot_error();
  EXPECT_EQ(stats.snapshots_saved(), 0u);
  // Writes succeed once the directory is there.
  fs::create_directories(missing);
  ASSERT_TRUE(wait_for(grpc::health::v1::HealthCheckResponse::SERVING));
  stats = Stats();
  EXPECT_GE(stats.snapshots_saved(), 1u);
  EXPECT_TRUE(stats.last_snapshot_error().empty());
  // The final snapshot cannot be written: the exit code says so.
  fs::remove_all(missing);
  EXPECT_EQ(fusiond->Stop(SIGTERM, 15s), 1);
}

}  // namespace
