// Map snapshots through LoadSnapshotFile: the .ot header, the node-structure check
// (CheckOtNodes) and OctoMap's reader. Files it sets aside are removed after every input.
#include <memory>

#include "common.h"
#include "fusion/service/persistence.h"

namespace fusion::fuzz {
namespace {

constexpr double kResolutionM = 0.05;  // the seeds' resolution; others take the kError path

// A loaded tree must be exactly the node data that was checked: the file's last 5 x size bytes
// (LoadSnapshotFile demands that length) are what OctoMap writes back for it.
Outcome CheckLoaded(const octomap::OcTree& tree, const std::uint8_t* data, std::size_t size) {
  const std::string again = service::SerializeOt(tree);
  const std::size_t node_bytes = 5 * tree.size();
  if (node_bytes > size || node_bytes > again.size()) return Broken("loaded more nodes than bytes");
  if (again.compare(again.size() - node_bytes, node_bytes,
                    reinterpret_cast<const char*>(data) + size - node_bytes, node_bytes) != 0) {
    return Broken("the loaded tree is not the node data that was checked");
  }
  return Accepted();
}

}  // namespace

Outcome RunSnapshot(const std::uint8_t* data, std::size_t size) {
  ClearScratch();
  const std::string path = WriteScratch("map.ot", data, size);
  if (path.empty()) return Broken("cannot write the scratch file");
  std::unique_ptr<octomap::OcTree> tree;
  std::string message;
  const service::LoadStatus status = service::LoadSnapshotFile(path, kResolutionM, &tree, &message);
  Outcome outcome;
  if (status == service::LoadStatus::kLoaded) {
    outcome = tree == nullptr ? Broken("loaded without a tree") : CheckLoaded(*tree, data, size);
  } else if (status == service::LoadStatus::kMissing) {
    outcome = Broken("a written file reported missing");
  } else {
    outcome = Rejected(message);
  }
  ClearScratch();
  return outcome;
}

}  // namespace fusion::fuzz
