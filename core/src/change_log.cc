#include "fusion/core/change_log.h"

#include <utility>

namespace fusion {

ChangeLog::ChangeLog(std::size_t max_regions) : max_regions_(max_regions) {}

void ChangeLog::Add(MapChanges changes) {
  if (changes.reset) {
    entries_.clear();
    logged_ = 0;
    complete_after_ = changes.version;
  }
  newest_ = changes.version;
  if (changes.reset) return;
  logged_ += changes.regions.size();
  entries_.push_back({changes.version, std::move(changes.regions)});
  while (entries_.size() > 1 && logged_ > max_regions_) {
    logged_ -= entries_.front().regions.size();
    complete_after_ = entries_.front().version;
    entries_.pop_front();
  }
}

bool ChangeLog::Since(std::uint64_t since, std::vector<MapRegion>* regions) const {
  if (since < complete_after_) return false;
  regions->clear();
  std::size_t versions = 0;
  for (const Entry& e : entries_) {
    if (e.version <= since) continue;
    regions->insert(regions->end(), e.regions.begin(), e.regions.end());
    ++versions;
  }
  if (versions > 1) NormaliseRegions(regions);
  return true;
}

}  // namespace fusion
