// A world that changes, end to end in core: the simulated SR-3000 at a fixed pose watches a
// crate 1.3 m ahead of the paper's board for 20 frames, then the crate is taken away. With
// change detection on (BeamGridOptions::change_run = 3) the crate's voxels are no longer
// occupied 3 frames after it is gone; without it the posterior has to be outvoted reading by
// reading and they still are.
#include <gtest/gtest.h>

#include <vector>

#include "fusion/core/world_map.h"
#include "fusion/sim/scene.h"
#include "fusion/sim/simulator.h"

namespace fusion {
namespace {

constexpr int kFramesWithCrate = 20;

struct CrateRun {
  std::size_t crate_voxels = 0;     // occupied voxels of the crate's front while it stood
  std::size_t still_occupied = 0;  // of those, occupied 3 frames after it was gone
  std::uint64_t changes = 0;          // beams restarted after the crate was gone
  std::uint64_t changes_before = 0;   // while the scene stood still: false alarms
};

CrateRun RemoveTheCrate(std::uint32_t change_run) {
  std::string error;
  const auto scene = sim::ParseScene(
      "rect board 1.75 0 0.2  0 1 0  0 0 1  1.2 1.0\n"
      "box crate 1.3 0 0.1  0.2 0.4 0.4  until 2\n",
      &error);
  EXPECT_TRUE(scene.has_value()) << error;
  const SensorSpec spec = sim::WithTessellation(*SensorPreset("sr3000"), 44, 36);
  sim::RangeSimulator simulator(*scene, spec, sim::SimOptions{});
  WorldMapOptions options;
  options.resolution_m = 0.04;
  options.beam_grid.change_run = change_run;
  WorldMap map(options);
  EXPECT_EQ(map.AddSensor("sr", spec), MapStatus::kOk);
  const Eigen::Isometry3d pose = sim::ForwardLookingPose(Eigen::Vector3d::Zero());
  CrateRun run;
  std::vector<octomap::OcTreeKey> crate;
  for (int frame = 0; frame < kFramesWithCrate + 3; ++frame) {
    const double t_s = frame * 0.1;  // the crate is gone from frame 20 on
    const sim::OrganizedCloud cloud = simulator.Capture(pose, t_s);
    IntegrationStats stats;
    EXPECT_EQ(map.Integrate("sr", pose, cloud.xyz.data(), cloud.size(), cloud.beyond_range,
                            &stats),
              MapStatus::kOk);
    (frame < kFramesWithCrate ? run.changes_before : run.changes) += stats.changes_detected;
    EXPECT_EQ(map.Render("sr"), MapStatus::kOk);
    if (frame == kFramesWithCrate - 1) {
      const octomap::OcTree& tree = map.tree();
      for (auto it = tree.begin_leafs(); it != tree.end_leafs(); ++it) {
        if (tree.isNodeOccupied(*it) && it.getX() > 1.1 && it.getX() < 1.45) {
          crate.push_back(it.getKey());
        }
      }
    }
  }
  run.crate_voxels = crate.size();
  for (const auto& key : crate) {
    const octomap::OcTreeNode* node = map.tree().search(key);
    if (node != nullptr && map.tree().isNodeOccupied(node)) ++run.still_occupied;
  }
  return run;
}

TEST(ChangingWorld, ACrateTakenAwayIsNotOccupiedThreeFramesLater) {
  const CrateRun on = RemoveTheCrate(3);
  ASSERT_GT(on.crate_voxels, 20u) << "the crate's front was mapped";
  EXPECT_EQ(on.changes_before, 0u) << "a static scene triggers nothing";
  EXPECT_GT(on.changes, 0u);
  EXPECT_LE(on.still_occupied, on.crate_voxels / 20)
      << on.still_occupied << " of " << on.crate_voxels << " still occupied";

  const CrateRun off = RemoveTheCrate(0);
  EXPECT_EQ(off.changes + off.changes_before, 0u);
  EXPECT_GT(off.still_occupied, off.crate_voxels / 2)
      << "without change detection the crate outlives 3 frames: " << off.still_occupied
      << " of " << off.crate_voxels;
}

}  // namespace
}  // namespace fusion
