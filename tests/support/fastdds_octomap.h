// Test helper: octomap_msgs/Octomap as a ROS 2 subscriber reads it, on the Fast DDS type
// fastddsgen makes of idl/ros2/octomap_msgs.idl (tests/support/ros2_fastdds.cmake).
#pragma once

#include <octomap/AbstractOcTree.h>
#include <octomap/OcTree.h>

#include <chrono>
#include <memory>
#include <sstream>

#include "fastdds_participant.h"
#include "octomap_msgsPubSubTypes.h"

namespace fusion::testing {

using Octomap = octomap_msgs::msg::dds_::Octomap_;

// What octomap_msgs::msgToMap makes of a message: createTree(id, resolution), then
// readBinaryData (binary) or readData (full) of `data`. Null unless it is an OcTree.
inline std::unique_ptr<octomap::OcTree> MsgToMap(const Octomap& msg) {
  std::unique_ptr<octomap::AbstractOcTree> tree(
      octomap::AbstractOcTree::createTree(msg.id(), msg.resolution()));
  auto* octree = dynamic_cast<octomap::OcTree*>(tree.get());
  if (octree == nullptr) return nullptr;
  std::stringstream data;
  data.write(reinterpret_cast<const char*>(msg.data().data()),
             static_cast<std::streamsize>(msg.data().size()));
  if (msg.binary()) {
    octree->readBinaryData(data);
  } else {
    octree->readData(data);
  }
  tree.release();
  return std::unique_ptr<octomap::OcTree>(octree);
}

// The newest sample a reader has, waiting up to `timeout` for the first.
template <class T>
bool TakeNewest(eprosima::fastdds::dds::DataReader* reader, T* sample,
                std::chrono::milliseconds timeout) {
  if (!TakeSample(reader, sample, timeout)) return false;
  while (TakeSample(reader, sample, std::chrono::milliseconds(0))) {
  }
  return true;
}

}  // namespace fusion::testing
