// The map's change log: what each published version changed, kept for clients that follow the
// map (the service's StreamUpdates) within a bound; the one log of the system.
#pragma once

#include <cstddef>
#include <cstdint>
#include <deque>
#include <vector>

#include "fusion/core/octree_merge.h"

namespace fusion {

// What one published version of the map changed.
struct MapChanges {
  std::uint64_t version = 0;
  // Earlier versions are gone (a reset, a loaded snapshot): read the whole map.
  bool reset = false;
  // Regions whose value changed, removed ones included (NormaliseRegions order).
  std::vector<MapRegion> regions;
};

class ChangeLog {
 public:
  // Older versions are forgotten once more than max_regions regions are logged (the newest
  // version is always kept whole).
  explicit ChangeLog(std::size_t max_regions);

  // Versions must ascend.
  void Add(MapChanges changes);
  // Regions changed after version `since` up to the newest (normalised: nested regions folded
  // into the outer one). False if the log does not reach back to `since`: the caller must read
  // the whole map.
  [[nodiscard]] bool Since(std::uint64_t since, std::vector<MapRegion>* regions) const;
  [[nodiscard]] std::uint64_t newest_version() const { return newest_; }
  [[nodiscard]] std::size_t logged_regions() const { return logged_; }

 private:
  struct Entry {
    std::uint64_t version;
    std::vector<MapRegion> regions;
  };
  std::size_t max_regions_;
  std::deque<Entry> entries_;
  std::size_t logged_ = 0;
  std::uint64_t complete_after_ = 0;  // Since(v) is exact for v >= this
  std::uint64_t newest_ = 0;
};

}  // namespace fusion
