// The ROS 2 output's parts without DDS: its options from the configuration, octomap_msgs'
// conversions (data = the .bt / .ot file without its header) and the occupied centres, with
// OctoMap itself as the oracle. The wire is tested from Fast DDS in
// tests/integration/fusiond_ros2_output_test.cc.
#include "fusion/service/ros2_output.h"

#include <gtest/gtest.h>
#include <octomap/AbstractOcTree.h>
#include <octomap/OcTree.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include "fusion/service/config.h"
#include "fusion/service/persistence.h"

namespace fusion::service {
namespace {

// A small tree: an occupied wall of 5 cm voxels, free space in front, and a pruned occupied
// block of 8 voxels (one coarse leaf).
octomap::OcTree SmallTree() {
  octomap::OcTree tree(0.05);
  // Voxel centres on integer steps (a sum of 0.05s drifts below a voxel boundary).
  for (int iy = -4; iy <= 4; ++iy) {
    for (int iz = 0; iz <= 4; ++iz) {
      const float y = 0.05f * iy + 0.025f, z = 0.05f * iz + 0.025f;
      tree.updateNode(octomap::point3d(1.025f, y, z), true);
      tree.updateNode(octomap::point3d(0.525f, y, z), false);
    }
  }
  for (int i = 0; i < 8; ++i) {
    tree.updateNode(octomap::point3d(2.025 + 0.05 * (i & 1), 0.025 + 0.05 * ((i >> 1) & 1),
                                     0.025 + 0.05 * (i >> 2)),
                    true);
  }
  tree.updateInnerOccupancy();
  tree.prune();
  return tree;
}

TEST(Ros2OutputOptions, DefaultsAreOffWithTheBinaryMapInTheMapFrame) {
  const auto options = Ros2OutputOptionsFromConfig(DefaultConfig());
  ASSERT_TRUE(options.ok()) << options.status().message();
  EXPECT_EQ(options->rate_hz, 0.0);
  EXPECT_FALSE(options->enabled());
  EXPECT_TRUE(options->binary);
  EXPECT_FALSE(options->full);
  EXPECT_FALSE(options->point_cloud_centers);
  EXPECT_EQ(options->map_frame, "map");
}

TEST(Ros2OutputOptions, FieldsAreReadAndBadRatesNamed) {
  auto config = DefaultConfig();
  auto* ros2 = config.mutable_ros2();
  ros2->set_map_frame("world");
  ros2->set_octomap_rate_hz(2.5);
  ros2->set_octomap_binary(false);
  ros2->set_octomap_full(true);
  ros2->set_point_cloud_centers(true);
  auto options = Ros2OutputOptionsFromConfig(config);
  ASSERT_TRUE(options.ok()) << options.status().message();
  EXPECT_TRUE(options->enabled());
  EXPECT_DOUBLE_EQ(options->rate_hz, 2.5);
  EXPECT_FALSE(options->binary);
  EXPECT_TRUE(options->full);
  EXPECT_TRUE(options->point_cloud_centers);
  EXPECT_EQ(options->map_frame, "world");
  // Every topic off: nothing to publish, whatever the rate.
  ros2->set_octomap_full(false);
  ros2->set_point_cloud_centers(false);
  EXPECT_FALSE(Ros2OutputOptionsFromConfig(config)->enabled());
  for (const double bad : {-1.0, 101.0, std::nan("")}) {
    ros2->set_octomap_rate_hz(bad);
    const auto refused = Ros2OutputOptionsFromConfig(config);
    ASSERT_FALSE(refused.ok()) << bad;
    EXPECT_NE(refused.status().message().find("ros2.octomap_rate_hz"), std::string::npos)
        << refused.status().message();
  }
}

// The configuration's validation checks the output's fields (fusiond refuses the file before
// anything starts); LoadConfigFile names the field.
TEST(Ros2OutputOptions, ValidateConfigRefusesABadRate) {
  auto config = DefaultConfig();
  config.mutable_ros2()->set_octomap_rate_hz(5.0);
  EXPECT_TRUE(ValidateConfig(config).ok()) << ValidateConfig(config).message();
  for (const double bad : {-0.5, 100.5, std::nan(""), HUGE_VAL}) {
    config.mutable_ros2()->set_octomap_rate_hz(bad);
    const Status refused = ValidateConfig(config);
    EXPECT_FALSE(refused.ok()) << bad;
    EXPECT_EQ(refused.message().rfind("ros2.octomap_rate_hz: ", 0), 0u) << refused.message();
  }
  const auto dir =
      std::filesystem::temp_directory_path() / ("ros2_output_rate_" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  const std::string file = (dir / "bad.pbtxt").string();
  { std::ofstream(file) << "ros2 { octomap_rate_hz: 1000 }\n"; }
  config = DefaultConfig();
  const Status loaded = LoadConfigFile(file, &config);
  std::filesystem::remove_all(dir);
  EXPECT_NE(loaded.message().find("ros2.octomap_rate_hz: 1000"), std::string::npos)
      << loaded.message();
}

// The compose profile ros2's configuration (docker/fusiond-ros2.pbtxt) and the documented
// example (docs/fusiond.example.pbtxt: off, the defaults) load and set the output up.
TEST(Ros2OutputOptions, TheShippedConfigurationsLoad) {
  // This file is tests/unit/service/ros2_output_test.cc; the files are at the root.
  const auto root = std::filesystem::path(__FILE__).parent_path() / "../../..";
  auto config = DefaultConfig();
  Status loaded = LoadConfigFile((root / "docker/fusiond-ros2.pbtxt").string(), &config);
  ASSERT_TRUE(loaded.ok()) << loaded.message();
  auto options = Ros2OutputOptionsFromConfig(config);
  ASSERT_TRUE(options.ok()) << options.status().message();
  EXPECT_TRUE(options->enabled());
  EXPECT_DOUBLE_EQ(options->rate_hz, 1.0);
  EXPECT_TRUE(options->binary && options->point_cloud_centers && !options->full);
  config = DefaultConfig();
  loaded = LoadConfigFile((root / "docs/fusiond.example.pbtxt").string(), &config);
  ASSERT_TRUE(loaded.ok()) << loaded.message();
  options = Ros2OutputOptionsFromConfig(config);
  ASSERT_TRUE(options.ok()) << options.status().message();
  EXPECT_FALSE(options->enabled());
  EXPECT_TRUE(options->binary);
}

// binaryMapToMsg: data is writeBinaryData's, i.e. the .bt file after its header.
TEST(Ros2OutputData, BinaryDataIsTheBtFileAfterItsHeaderAndReadsBackTheSameTree) {
  const octomap::OcTree tree = SmallTree();
  const std::string data = OctomapBinaryData(tree, StateThresholds{});
  const std::string bt = SerializeBt(tree, StateThresholds{});
  // Without a dead band the classified writer writes what OctoMap's writeBinary does.
  std::ostringstream octomaps_data(std::ios::binary), octomaps_bt(std::ios::binary);
  tree.writeBinaryData(octomaps_data);
  tree.writeBinaryConst(octomaps_bt);
  EXPECT_EQ(data, octomaps_data.str());
  EXPECT_EQ(bt, octomaps_bt.str());
  ASSERT_GT(bt.size(), data.size());
  EXPECT_EQ(bt.substr(bt.size() - data.size()), data);
  EXPECT_EQ(bt.substr(0, bt.size() - data.size()).rfind("data\n"), bt.size() - data.size() - 5);
  octomap::OcTree read(0.05);
  std::istringstream in(data);
  read.readBinaryData(in);
  EXPECT_EQ(read.getNumLeafNodes(), tree.getNumLeafNodes());
  const auto* wall = read.search(1.025, 0.025, 0.125);
  const auto* in_front = read.search(0.525, 0.025, 0.125);
  ASSERT_TRUE(wall != nullptr && in_front != nullptr);
  EXPECT_TRUE(read.isNodeOccupied(wall));
  EXPECT_FALSE(read.isNodeOccupied(in_front));
}

// One classification everywhere (issue 11): the binary map says what queries say (StateOf):
// a voxel in the dead band is unknown in it (absent), not free, and one just above OctoMap's 0.5
// but below occupied_threshold is not occupied.
TEST(Ros2OutputData, BinaryDataClassifiesWithTheServicesThresholds) {
  octomap::OcTree tree(0.05);
  const octomap::point3d occupied(0.025f, 0.025f, 0.025f), free(0.525f, 0.025f, 0.025f),
      weak(1.025f, 0.025f, 0.025f), weakly_free(1.525f, 0.025f, 0.025f);
  tree.setNodeValue(occupied, 2.0f);     // p 0.88
  tree.setNodeValue(free, -2.0f);        // p 0.12
  tree.setNodeValue(weak, 0.1f);         // p 0.525: unknown by 0.55 / 0.45
  tree.setNodeValue(weakly_free, -0.1f); // p 0.475: unknown too
  const StateThresholds service{0.55, 0.45};
  for (const std::string& data :
       {OctomapBinaryData(tree, service), SerializeBt(tree, service)}) {
    octomap::OcTree read(0.05);
    std::istringstream in(data);
    if (data.rfind("# Octomap", 0) == 0) {
      ASSERT_TRUE(read.readBinary(in));
    } else {
      read.readBinaryData(in);
    }
    const auto* o = read.search(occupied);
    const auto* f = read.search(free);
    ASSERT_TRUE(o != nullptr && f != nullptr);
    EXPECT_TRUE(read.isNodeOccupied(o));
    EXPECT_FALSE(read.isNodeOccupied(f));
    EXPECT_EQ(read.search(weak), nullptr) << "a dead-band voxel is unknown, not in the map";
    EXPECT_EQ(read.search(weakly_free), nullptr);
  }
  // Without a dead band (core's one threshold) every leaf stays, as OctoMap writes it.
  octomap::OcTree read(0.05);
  std::istringstream in(OctomapBinaryData(tree, StateThresholds{}));
  read.readBinaryData(in);
  EXPECT_EQ(read.getNumLeafNodes(), tree.getNumLeafNodes());
  ASSERT_NE(read.search(weak), nullptr);
  EXPECT_TRUE(read.isNodeOccupied(read.search(weak)));
}

// fullMapToMsg: data is writeData's, i.e. the .ot file after its header, log-odds and all.
TEST(Ros2OutputData, FullDataIsTheOtFileAfterItsHeaderAndKeepsTheLogOdds) {
  const octomap::OcTree tree = SmallTree();
  const std::string data = OctomapFullData(tree);
  const std::string ot = SerializeOt(tree);
  ASSERT_GT(ot.size(), data.size());
  EXPECT_EQ(ot.substr(ot.size() - data.size()), data);
  std::unique_ptr<octomap::AbstractOcTree> created(
      octomap::AbstractOcTree::createTree(tree.getTreeType(), tree.getResolution()));
  auto* read = dynamic_cast<octomap::OcTree*>(created.get());
  ASSERT_NE(read, nullptr);
  std::istringstream in(data);
  read->readData(in);
  ASSERT_EQ(read->getNumLeafNodes(), tree.getNumLeafNodes());
  for (auto it = tree.begin_leafs(), end = tree.end_leafs(); it != end; ++it) {
    const auto* node = read->search(it.getKey(), it.getDepth());
    ASSERT_NE(node, nullptr);
    EXPECT_EQ(node->getLogOdds(), it->getLogOdds());
  }
}

TEST(Ros2OutputData, CentresAreTheOccupiedLeavesIncludingPrunedOnes) {
  const octomap::OcTree tree = SmallTree();
  const std::vector<float> xyz = OccupiedLeafCentres(tree);
  ASSERT_EQ(xyz.size() % 3, 0u);
  std::size_t occupied = 0;
  for (auto it = tree.begin_leafs(), end = tree.end_leafs(); it != end; ++it) {
    occupied += tree.isNodeOccupied(*it) ? 1 : 0;
  }
  EXPECT_EQ(xyz.size() / 3, occupied);
  // 9 x 5 wall voxels (one voxel thick: none pruned) and the 8-voxel block as one leaf.
  EXPECT_EQ(occupied, 9u * 5u + 1u);
  bool block_centre = false;
  for (std::size_t i = 0; i < xyz.size(); i += 3) {
    block_centre =
        block_centre || (std::abs(xyz[i] - 2.05f) < 1e-4f && std::abs(xyz[i + 1] - 0.05f) < 1e-4f &&
                         std::abs(xyz[i + 2] - 0.05f) < 1e-4f);
  }
  EXPECT_TRUE(block_centre) << "the pruned block's centre (2.05, 0.05, 0.05) is missing";
}

}  // namespace
}  // namespace fusion::service
