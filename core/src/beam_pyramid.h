// Internal to core (the projective render): what the render keeps of each beam, and the
// pyramid of those aggregates that answers "what do the beams over this rectangle say?" for an
// octree block in a few look-ups.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstring>
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

  // The four floats at once (the pyramid's queries add many): lane 0 the minimum, lanes 1-3
  // the maximum, each as std::min / std::max take it.
  void Add(const Aggregate& o) {
    using F4 = float __attribute__((vector_size(16)));
    F4 a, b;
    std::memcpy(&a, this, sizeof a);  // the object's first 16 bytes: its four floats
    std::memcpy(&b, &o, sizeof b);
    const F4 lower = b < a ? b : a;
    const F4 upper = a < b ? b : a;
    const F4 sum = __builtin_shufflevector(lower, upper, 0, 5, 6, 7);
    std::memcpy(static_cast<void*>(this), &sum, sizeof sum);
    touched += o.touched;
    beams += o.beams;
  }
};
static_assert(offsetof(Aggregate, min_free_end) == 0 && offsetof(Aggregate, max_free_end) == 4 &&
                  offsetof(Aggregate, max_far) == 8 && offsetof(Aggregate, max_free_value) == 12,
              "Aggregate::Add reads its four floats as one vector");

// Columns [col_lo, col_hi] and rows [row_lo, row_hi] of a beam grid (inclusive).
struct BeamExtent {
  int col_lo = 0, col_hi = -1, row_lo = 0, row_hi = -1;
  [[nodiscard]] bool empty() const { return col_hi < col_lo || row_hi < row_lo; }
  [[nodiscard]] bool Holds(int col, int row) const {
    return col >= col_lo && col <= col_hi && row >= row_lo && row <= row_hi;
  }
};

// Min / max images of the beam grid, halved level by level: a rectangle of beams is answered
// from at most 5 x 5 cells of the level where its larger side spans four cells.
class BeamPyramid {
 public:
  // Rectangles of at most this many beams are read beam by beam, larger ones from the pyramid.
  static constexpr int kExactBeams = 32;

  BeamPyramid() = default;
  BeamPyramid(int cols, int rows, std::vector<Aggregate> beams) {
    levels_.push_back({cols, rows, std::move(beams)});
    Build();
  }

  // Level 0 for cols x rows beams, every aggregate empty, to be filled before Build (the
  // levels' memory is kept from the pyramid before: a sensor's renders reuse it).
  std::vector<Aggregate>& Beams(int cols, int rows) {
    if (levels_.empty()) levels_.emplace_back();
    levels_[0].cols = cols;
    levels_[0].rows = rows;
    levels_[0].cells.assign(static_cast<std::size_t>(cols) * rows, Aggregate{});
    return levels_[0].cells;
  }

  // The levels above 0, each halving the one below, up to a single cell.
  void Build() {
    std::size_t l = 0;
    while (levels_[l].cols > 1 || levels_[l].rows > 1) {
      if (levels_.size() == l + 1) levels_.emplace_back();
      const Level& below = levels_[l];
      Level& up = levels_[l + 1];
      up.cols = (below.cols + 1) / 2;
      up.rows = (below.rows + 1) / 2;
      up.cells.assign(static_cast<std::size_t>(up.cols) * up.rows, Aggregate{});
      for (int r = 0; r < below.rows; ++r) {
        for (int c = 0; c < below.cols; ++c) {
          up.cells[static_cast<std::size_t>(r / 2) * up.cols + c / 2].Add(
              below.cells[static_cast<std::size_t>(r) * below.cols + c]);
        }
      }
      ++l;
    }
    levels_.resize(l + 1);
  }

  // The smallest rectangle holding every touched beam (empty: none is). Beyond it no ray runs:
  // the render's field of view ends there, and the beams there are left out of the counts
  // (Aggregate::beams 0), so that a block near its edge is not held undecided by pyramid cells
  // reaching past it (a sensor period's grid reaches past the sensor's own, SensorPeriods).
  void SetTouchedExtent(const BeamExtent& extent) { extent_ = extent; }
  [[nodiscard]] const BeamExtent& touched_extent() const { return extent_; }
  [[nodiscard]] std::size_t MemoryBytes() const {
    std::size_t bytes = 0;
    for (const Level& level : levels_) bytes += level.cells.capacity() * sizeof(Aggregate);
    return bytes;
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
    int cols = 0;
    int rows = 0;
    std::vector<Aggregate> cells;
  };
  std::vector<Level> levels_;
  BeamExtent extent_;
};

}  // namespace fusion::detail
