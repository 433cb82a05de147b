#include "fusion/core/rendered_grid.h"

#include <algorithm>

#include "fusion/core/local_grid.h"

namespace fusion {
namespace {

std::uint64_t Spread(std::uint64_t x) {
  x &= 0xffff;
  x = (x | (x << 16)) & 0x0000ff0000ffULL;
  x = (x | (x << 8)) & 0x00f00f00f00fULL;
  x = (x | (x << 4)) & 0x0c30c30c30c3ULL;
  x = (x | (x << 2)) & 0x249249249249ULL;
  return x;
}

std::uint64_t Compact(std::uint64_t x) {
  x &= 0x249249249249ULL;
  x = (x | (x >> 2)) & 0x0c30c30c30c3ULL;
  x = (x | (x >> 4)) & 0x00f00f00f00fULL;
  x = (x | (x >> 8)) & 0x0000ff0000ffULL;
  x = (x | (x >> 16)) & 0xffffULL;
  return x;
}

}  // namespace

std::uint64_t MortonOf(const octomap::OcTreeKey& key) {
  return Spread(key.k[0]) | (Spread(key.k[1]) << 1) | (Spread(key.k[2]) << 2);
}

octomap::OcTreeKey KeyOfMorton(std::uint64_t code) {
  return octomap::OcTreeKey(static_cast<octomap::key_type>(Compact(code)),
                            static_cast<octomap::key_type>(Compact(code >> 1)),
                            static_cast<octomap::key_type>(Compact(code >> 2)));
}

octomap::OcTreeKey NodeKey(std::uint64_t code, unsigned depth) {
  octomap::OcTreeKey key = KeyOfMorton(MortonAtDepth(code, depth));
  if (depth < kTreeDepth) {
    const auto half = static_cast<octomap::key_type>(1u << (kTreeDepth - depth - 1));
    for (auto& k : key.k) k = static_cast<octomap::key_type>(k + half);
  }
  return key;
}

RenderedGrid RenderedGrid::FromLocalGrid(const LocalGrid& local) {
  RenderedGrid out(local.resolution_m());
  out.nodes_.reserve(local.size());
  local.ForEachLogOdds([&](const octomap::OcTreeKey& key, float l) {
    if (l == 0.0f) return;  // crossed, but left unknown (the voxel rule's dead band)
    out.nodes_.push_back({MortonOf(key), l, static_cast<std::uint8_t>(kTreeDepth)});
  });
  std::sort(out.nodes_.begin(), out.nodes_.end(),
            [](const MapNode& a, const MapNode& b) { return a.code < b.code; });
  return out;
}

std::uint64_t RenderedGrid::VoxelCount() const {
  std::uint64_t n = 0;
  for (const MapNode& node : nodes_) n += MortonSpan(node.depth);
  return n;
}

std::optional<float> RenderedGrid::LogOddsAt(const octomap::OcTreeKey& key) const {
  const std::uint64_t code = MortonOf(key);
  // The last node starting at or before the code holds it, if any does.
  auto it = std::upper_bound(nodes_.begin(), nodes_.end(), code,
                             [](std::uint64_t c, const MapNode& n) { return c < n.code; });
  if (it == nodes_.begin()) return std::nullopt;
  --it;
  if (code >= it->code + MortonSpan(it->depth)) return std::nullopt;
  return it->log_odds;
}

bool RenderedGrid::IsValid() const {
  std::uint64_t next = 0;
  for (const MapNode& n : nodes_) {
    if (n.depth > kTreeDepth || MortonAtDepth(n.code, n.depth) != n.code || n.code < next) {
      return false;
    }
    next = n.code + MortonSpan(n.depth);
  }
  return true;
}

}  // namespace fusion
