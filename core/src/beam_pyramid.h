// Internal to core (the projective render): what the render keeps of each beam, and the
// pyramid of those aggregates that answers "what do the beams over this rectangle say?" for an
// octree block in a few look-ups.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <utility>
#include <vector>

namespace fusion::detail {

// What the pyramid keeps of a set of beams (one beam at level 0).
struct Aggregate {
  static constexpr float kInf = std::numeric_limits<float>::infinity();
  float min_free_end = kInf;     // nearest end of a free zone (m)
  float max_free_end = -kInf;    // farthest end of a free zone
  float max_far = -kInf;         // no voxel traced by (or in the oracle, crossed by) a ray of these
                                 // beams starts at or beyond this range
  float max_free_value = -kInf;  // strongest (least negative) free-zone evidence
  std::uint32_t touched = 0;
  std::uint32_t beams = 0;

  void Add(const Aggregate& o) {
    min_free_end = std::min(min_free_end, o.min_free_end);
    max_free_end = std::max(max_free_end, o.max_free_end);
    max_far = std::max(max_far, o.max_far);
    max_free_value = std::max(max_free_value, o.max_free_value);
    touched += o.touched;
    beams += o.beams;
  }
};

// Min / max images of the beam grid, halved level by level: a rectangle of beams is answered
// from at most 5 x 5 cells of the level where its larger side spans four cells.
class BeamPyramid {
 public:
  // Rectangles of at most this many beams are read beam by beam, larger ones from the pyramid.
  static constexpr int kExactBeams = 32;

  BeamPyramid(int cols, int rows, std::vector<Aggregate> beams) {
    levels_.push_back({cols, rows, std::move(beams)});
    while (levels_.back().cols > 1 || levels_.back().rows > 1) {
      const Level& below = levels_.back();
      Level up{(below.cols + 1) / 2, (below.rows + 1) / 2, {}};
      up.cells.resize(static_cast<std::size_t>(up.cols) * up.rows);
      for (int r = 0; r < below.rows; ++r) {
        for (int c = 0; c < below.cols; ++c) {
          up.cells[static_cast<std::size_t>(r / 2) * up.cols + c / 2].Add(
              below.cells[static_cast<std::size_t>(r) * below.cols + c]);
        }
      }
      levels_.push_back(std::move(up));
    }
  }

  [[nodiscard]] const Aggregate& Beam(int col, int row) const {
    return levels_[0].cells[static_cast<std::size_t>(row) * levels_[0].cols + col];
  }
  // Beams of columns [c0, c1] and rows [r0, r1] (a superset, for large rectangles).
  [[nodiscard]] Aggregate Query(int c0, int c1, int r0, int r1) const {
    Aggregate out;
    const int w = c1 - c0 + 1;
    const int h = r1 - r0 + 1;
    std::size_t l = 0;
    if (w * h > kExactBeams) {
      // The coarsest level whose cells still give a bound within 4 x 4 cells of the rectangle.
      while ((4 << l) < std::max(w, h)) ++l;
      l = std::min(l, levels_.size() - 1);
    }
    const Level& level = levels_[l];
    for (int r = r0 >> l; r <= (r1 >> l); ++r) {
      for (int c = c0 >> l; c <= (c1 >> l); ++c) {
        out.Add(level.cells[static_cast<std::size_t>(r) * level.cols + c]);
      }
    }
    return out;
  }

 private:
  struct Level {
    int cols;
    int rows;
    std::vector<Aggregate> cells;
  };
  std::vector<Level> levels_;
};

}  // namespace fusion::detail
