// A world that changes, end to end in core: the simulated SR-3000 at a fixed pose watches a
// crate 1.3 m ahead of the paper's board for 20 frames, then the crate is taken away. With
// change detection on (BeamGridOptions::change_run = 3) the crate's voxels are no longer
// occupied 3 frames after it is gone; without it the posterior has to be outvoted reading by
// reading and they still are. Then the dynamic scenarios of fusion/sim/dynamic_scenario.h at
// 30 Hz: the crate taken away before a still and a driving sensor, a person walking through.
#include <gtest/gtest.h>

#include <vector>

#include "fusion/core/world_map.h"
#include "fusion/sim/dynamic_scenario.h"
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

// The scenarios at 44 x 36 beams and 4 cm (seconds, not minutes; BENCHMARKS.md has the SR-3000's
// own 176 x 144 at 2 cm, dynamic_scenarios).
class DynamicScenarioTest : public ::testing::Test {
 protected:
  DynamicScenarioTest() : spec_(sim::WithTessellation(*SensorPreset("sr3000"), 44, 36)) {
    options_.resolution_m = 0.04;
  }
  // The run, and the same run without the object (its static accuracy, its false alarms).
  void Run(const sim::DynamicScenario& scenario, sim::DynamicResult* run,
           sim::DynamicResult* still) {
    *run = sim::RunDynamicScenario(scenario, options_);
    sim::DynamicScenario without = scenario;
    without.without_object = true;
    *still = sim::RunDynamicScenario(without, options_);
    EXPECT_EQ(still->changes_detected, 0u) << scenario.name << ": a false alarm";
    EXPECT_GE(run->static_accuracy.recall, still->static_accuracy.recall - 0.005) << scenario.name;
    EXPECT_LE(run->static_accuracy.brier, still->static_accuracy.brier + 0.0005) << scenario.name;
  }
  SensorSpec spec_;
  WorldMapOptions options_;
};

TEST_F(DynamicScenarioTest, ACrateTakenAwayIsClearWithinThreeFramesStillOrDriving) {
  for (const bool moving : {false, true}) {
    sim::DynamicResult run, still;
    Run(sim::CrateRemovedScenario(spec_, moving), &run, &still);
    ASSERT_GT(run.trail_voxels, 20u) << "the crate was mapped";
    const int clear = run.ClearFrames(0.05);
    EXPECT_GE(clear, 1);
    EXPECT_LE(clear, 3) << (moving ? "driving" : "still");
  }
  // Without change detection the still sensor's posterior keeps the crate.
  options_.beam_grid.change_run = 0;
  const sim::DynamicResult off =
      sim::RunDynamicScenario(sim::CrateRemovedScenario(spec_, false), options_);
  EXPECT_EQ(off.ClearFrames(0.05), -1);
  EXPECT_GT(off.TrailAt(30), 0.5);
}

TEST_F(DynamicScenarioTest, APersonWalkingThroughLeavesNoTrailASecondLater) {
  for (const bool moving : {false, true}) {
    sim::DynamicResult run, still;
    Run(sim::WalkerScenario(spec_, moving), &run, &still);
    ASSERT_GT(run.trail_voxels, 100u) << "the person was mapped";
    EXPECT_GE(run.TrailAt(30), 0.0) << "voxels seen a second after the person left them";
    EXPECT_LE(run.TrailAt(30), 0.05) << (moving ? "driving" : "still");
  }
}

}  // namespace
}  // namespace fusion
