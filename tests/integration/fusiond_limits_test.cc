// Every expensive request is bounded: FindPlanes and QueryBox refuse work over their limits
// before they start, and a deadline ends the most expensive allowed call promptly, leaving
// the server's CPU idle (issue 14, defect 3).
#include <gtest/gtest.h>

#include <octomap/OcTree.h>

#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>

#include "../support/fusiond_fixture.h"

namespace {

using namespace fusion::testing;  // NOLINT: the fixture and its helpers
using namespace std::chrono_literals;
namespace v1 = fusion::v1;

// The fields of a /proc/.../stat file, numbered as proc(5) numbers them (field 1 at [1]).
std::vector<std::string> StatFields(const std::filesystem::path& path) {
  std::ifstream in(path);
  std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const auto paren = text.rfind(')');
  if (paren == std::string::npos) return {};
  // [1] pid and [2] comm (which may hold spaces) are not needed: placeholders.
  std::vector<std::string> fields{"", "pid", "comm"};
  std::istringstream rest(text.substr(paren + 2));
  for (std::string field; rest >> field;) fields.push_back(field);
  return fields;
}

// CPU time (user + system, fields 14 and 15) fusiond has used, in clock ticks.
long CpuTicks(pid_t pid) {
  const auto f = StatFields("/proc/" + std::to_string(pid) + "/stat");
  return f.size() > 15 ? std::stol(f[14]) + std::stol(f[15]) : 0;
}

// The nice values (field 19) of fusiond's threads.
std::set<int> NiceValues(pid_t pid) {
  std::set<int> values;
  for (const auto& task :
       std::filesystem::directory_iterator("/proc/" + std::to_string(pid) + "/task")) {
    const auto f = StatFields(task.path() / "stat");
    if (f.size() > 19) values.insert(std::stoi(f[19]));
  }
  return values;
}

// Runs `call` with a 0.3 s deadline; expects DEADLINE_EXCEEDED within 0.5 s and fusiond's CPU
// idle from 100 ms after the answer (less than a third of one core over the next 300 ms).
// With limits.max_heavy_queries 1 the previous call's slot may still be held: on a loaded
// machine its task can wait on the low-priority pool (nice 13) after its deadline passed, and
// then ends at once. Such a refusal (RESOURCE_EXHAUSTED) is retried for up to 10 s.
template <typename Call>
void ExpectEndsWithTheDeadline(pid_t pid, const char* what, Call&& call) {
  auto start = std::chrono::steady_clock::now();
  grpc::Status status = call(In(300ms));
  for (int retry = 0; status.error_code() == grpc::StatusCode::RESOURCE_EXHAUSTED && retry < 50;
       ++retry) {
    std::this_thread::sleep_for(200ms);
    start = std::chrono::steady_clock::now();
    status = call(In(300ms));
  }
  const auto elapsed = std::chrono::steady_clock::now() - start;
  EXPECT_EQ(status.error_code(), grpc::StatusCode::DEADLINE_EXCEEDED)
      << what << ": " << status.error_message();
  EXPECT_LT(elapsed, 500ms) << what;
  std::this_thread::sleep_for(100ms);
  const long before = CpuTicks(pid);
  std::this_thread::sleep_for(300ms);
  const long used_ms = (CpuTicks(pid) - before) * 1000 / sysconf(_SC_CLK_TCK);
  EXPECT_LT(used_ms, 100) << what << ": the server went on working after the deadline";
}

class FusiondLimitsTest : public FusiondServiceTest {
 protected:
  // A snapshot fusiond loads at start: one free leaf at depth 8 (a 12.8 m cube of 5 cm voxels
  // from the origin, every one known) and a plane of 10 000 occupied voxels at z = 6 m.
  void WriteBlockSnapshot() {
    octomap::OcTree tree(0.05);
    const octomap::OcTreeKey corner = tree.coordToKey(0.01, 0.01, 0.01);
    tree.updateNode(corner, false);  // a chain of nodes from the root to the corner voxel
    std::vector<octomap::OcTreeNode*> chain{tree.getRoot()};
    for (unsigned depth = 0; depth < 16; ++depth) {
      chain.push_back(tree.getNodeChild(chain.back(), octomap::computeChildIdx(corner, 15 - depth)));
    }
    // Bottom up to depth 8: all eight children free leaves, then pruned into their parent.
    for (int depth = 15; depth >= 8; --depth) {
      octomap::OcTreeNode* parent = chain[static_cast<std::size_t>(depth)];
      for (unsigned i = 0; i < 8; ++i) {
        if (!tree.nodeChildExists(parent, i)) tree.createNodeChild(parent, i);
        tree.getNodeChild(parent, i)->setLogOdds(-2.0f);
      }
      ASSERT_TRUE(tree.pruneNode(parent));
    }
    for (int x = 0; x < 100; ++x) {
      for (int y = 0; y < 100; ++y) tree.setNodeValue(0.025 + 0.05 * x, 0.025 + 0.05 * y, 6.025, 2.0f);
    }
    tree.updateInnerOccupancy();
    ASSERT_TRUE(tree.write(snapshot_));
  }

  grpc::Status FindPlanes(double angle_step_deg, double distance_step_m,
                          std::chrono::system_clock::time_point deadline) {
    grpc::ClientContext context;
    context.set_deadline(deadline);
    v1::FindPlanesRequest request;
    request.set_angle_step_deg(angle_step_deg);
    request.set_distance_step_m(distance_step_m);
    v1::FindPlanesResponse reply;
    return stub_->FindPlanes(&context, request, &reply);
  }
};

TEST_F(FusiondLimitsTest, ExpensiveRequestsAreRefusedOrEndWithTheirDeadline) {
  WriteBlockSnapshot();
  {
    std::ifstream in(config_);
    std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    const std::string box = "max_box_voxels: 2000000";
    text.replace(text.find(box), box.size(), "max_box_voxels: 100000000 max_heavy_queries: 1");
    std::ofstream(config_) << text;
  }
  auto fusiond = Start();
  ASSERT_TRUE(fusiond);
  ASSERT_GE(Stats().map_leaves(), 10000u) << "the snapshot was not loaded";
  ASSERT_EQ(Occupancy({1.025, 1.025, 6.025}).state(), v1::VOXEL_STATE_OCCUPIED);
  ASSERT_EQ(Occupancy({1.025, 1.025, 3.025}).state(), v1::VOXEL_STATE_FREE);
  // 0.1 degree and 1 mm bins: 6.5 M normals x 9000 distance bins. Refused before it starts.
  const grpc::Status refused = FindPlanes(0.1, 0.001, In(10s));
  EXPECT_EQ(refused.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED) << refused.error_message();
  EXPECT_NE(refused.error_message().find("limits.max_plane_cells"), std::string::npos);
  // 0.2 degree and 10 m bins fit the accumulator bound (1.6 M normals x 5 cells), but each of
  // the 10 000 voxels casts 1.6 M votes: seconds of work the deadline cuts short.
  ExpectEndsWithTheDeadline(fusiond->pid(), "FindPlanes", [&](auto deadline) {
    return FindPlanes(0.2, 10.0, deadline);
  });
  // A box of 250^3 voxels inside the known cube asking for unknown voxels: every key is looked
  // up and none matches.
  ExpectEndsWithTheDeadline(fusiond->pid(), "QueryBox", [&](auto deadline) {
    grpc::ClientContext context;
    context.set_deadline(deadline);
    v1::QueryBoxRequest request;
    *request.mutable_min() = P({0.01, 0.01, 0.01});
    *request.mutable_max() = P({12.49, 12.49, 12.49});
    request.add_states(v1::VOXEL_STATE_UNKNOWN);
    v1::QueryBoxResponse reply;
    return stub_->QueryBox(&context, request, &reply);
  });
  // One expensive call at a time (limits.max_heavy_queries: 1): a second is shed at once.
  std::thread running([&] { (void)FindPlanes(0.2, 10.0, In(1500ms)); });
  std::this_thread::sleep_for(500ms);
  const grpc::Status shed = FindPlanes(45.0, 1.0, In(5s));
  running.join();
  EXPECT_EQ(shed.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED) << shed.error_message();
  EXPECT_NE(shed.error_message().find("limits.max_heavy_queries"), std::string::npos);
  // The server ends the cancelled search within a poll of the deadline, then frees the slot.
  grpc::Status again = FindPlanes(45.0, 1.0, In(5s));
  for (int i = 0; i < 200 && !again.ok(); ++i) {
    std::this_thread::sleep_for(10ms);
    again = FindPlanes(45.0, 1.0, In(5s));
  }
  EXPECT_TRUE(again.ok()) << "the slot is not free again: " << again.error_message();
  // The expensive calls run at limits.heavy_query_nice (13), the fusion worker at 10, gRPC's
  // and DDS's threads at 0.
  EXPECT_EQ(NiceValues(fusiond->pid()), (std::set<int>{0, 10, 13}));
  EXPECT_EQ(fusiond->Stop(SIGTERM, 15s), 0);
}

// A QueryBox returns only voxels that share space with the box: the 12.8 m free leaf of the
// snapshot ends at x = 12.8 m and must not come back for a box from x = 12.825 m (OctoMap's
// bbx iterator yields it).
TEST_F(FusiondLimitsTest, QueryBoxReturnsOnlyVoxelsThatOverlapTheBox) {
  WriteBlockSnapshot();
  auto fusiond = Start();
  ASSERT_TRUE(fusiond);
  const auto query = [&](const Eigen::Vector3d& lo, const Eigen::Vector3d& hi) {
    grpc::ClientContext context;
    context.set_deadline(In(10s));
    v1::QueryBoxRequest request;
    *request.mutable_min() = P(lo);
    *request.mutable_max() = P(hi);
    request.add_states(v1::VOXEL_STATE_FREE);
    request.add_states(v1::VOXEL_STATE_OCCUPIED);
    v1::QueryBoxResponse reply;
    EXPECT_TRUE(stub_->QueryBox(&context, request, &reply).ok());
    return reply;
  };
  // Whether a voxel shares space (more than a face) with the box.
  const auto overlaps = [](const v1::Voxel& v, const Eigen::Vector3d& lo, const Eigen::Vector3d& hi) {
    const Eigen::Vector3d c(v.center().x(), v.center().y(), v.center().z());
    const Eigen::Vector3d half = Eigen::Vector3d::Constant(0.5 * v.size_m() - 1e-6);
    return ((c - half).array() <= hi.array()).all() && ((c + half).array() >= lo.array()).all();
  };
  const Eigen::Vector3d lo(12.825, 0.1, 0.1), hi(13.5, 1.0, 1.0);
  const v1::QueryBoxResponse beside = query(lo, hi);
  for (const auto& v : beside.voxels()) {
    ADD_FAILURE() << "a voxel of " << v.size_m() << " m at (" << v.center().x() << ", "
                  << v.center().y() << ", " << v.center().z() << ") outside the box";
  }
  // A box reaching 12.7 m holds free space of the cube: found, and nothing beyond the box.
  const Eigen::Vector3d inside_lo(12.7, 0.1, 0.1);
  const v1::QueryBoxResponse inside = query(inside_lo, hi);
  EXPECT_GE(inside.voxels_size(), 1);
  for (const auto& v : inside.voxels()) EXPECT_TRUE(overlaps(v, inside_lo, hi)) << v.size_m();
  EXPECT_EQ(fusiond->Stop(SIGTERM, 15s), 0);
}

}  // namespace
