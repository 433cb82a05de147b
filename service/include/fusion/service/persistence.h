// Map snapshots on disk in OctoMap's .ot format: written atomically (temporary file, fsync,
// rename, fsync of the directory), loaded at start, corrupt files set aside, never
// overwritten silently.
#pragma once

#include <octomap/OcTree.h>

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "fusion/core/status.h"
#include "fusion/service/conversions.h"

namespace fusion::service {

// Writes `tree` to `path` atomically. *bytes receives the file size.
[[nodiscard]] Status WriteSnapshotFile(const octomap::OcTree& tree, const std::string& path,
                                       std::uint64_t* bytes);

enum class LoadStatus {
  kLoaded,
  kMissing,  // no file: start empty
  kCorrupt,  // unreadable or inconsistent: renamed to <path>.corrupt-<UTC time>
  kError,    // readable but unusable (e.g. another resolution), or cannot set aside: refuse
};

// Loads a snapshot written by WriteSnapshotFile (or any OcTree .ot file). Checks that the
// declared node count matches the data before parsing, so a truncated file is detected
// instead of being half-loaded. *message explains anything but kLoaded / kMissing.
LoadStatus LoadSnapshotFile(const std::string& path, double expected_resolution_m,
                            std::unique_ptr<octomap::OcTree>* tree, std::string* message);

// Removes the temporary files WriteSnapshotFile leaves when its process is killed mid-write
// (<path>.tmp-<pid>, for a pid that no longer runs); returns their names.
std::vector<std::string> RemoveStaleTempFiles(const std::string& path);

// The tree as maximum-likelihood binary data (OcTree::writeBinaryData's format, the .bt file
// after its header and octomap_msgs' binary `data`), classified as queries classify (StateOf):
// occupied and free leaves by t, the leaves t calls unknown left out, as are subtrees that hold
// nothing else. *nodes: the nodes a reader creates (the header's size).
std::string MaximumLikelihoodData(const octomap::OcTree& tree, const StateThresholds& t,
                                  std::size_t* nodes);

// Serialises a tree as .ot (full, log-odds) or .bt (maximum likelihood, classified by t) bytes.
std::string SerializeOt(const octomap::OcTree& tree);
std::string SerializeBt(const octomap::OcTree& tree, const StateThresholds& t);

}  // namespace fusion::service
