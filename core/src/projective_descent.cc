#include "projective_descent.h"

#include <octomap/OcTree.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <limits>
#include <optional>
#include <vector>

#include "beam_trace.h"
#include "block_geometry.h"
#include "fusion/core/voxel_traversal.h"

namespace fusion::detail {
namespace {

double Square(double v) { return v * v; }

// The top-down visit of the octree. A block whose beams (the pyramid's superset of them) are all
// touched and free through it, but which is not wholly inside the field of view or beyond r_min,
// passes that verdict down: its parts are then decided by geometry alone.
class Descent {
 public:
  // pyramid: every beam's Aggregate; traced: the voxels the rays crossed in the beams' first-hit
  // mass; t_start: where every ray starts; global_far: the largest Aggregate::max_far.
  Descent(const BeamGrid& grid, const Eigen::Isometry3d& T_world_sensor,
          const RenderOptions& options, const BeamPyramid& pyramid, const LocalGrid& traced,
          double t_start, float global_far, const SaturatedFree* skip, DescentBuffers* buffers,
          RenderedGrid* out, RenderStats* stats);

  static constexpr std::size_t kMaxOthers = 8;

  // The map's history over a block, and the other live contributions' nodes in it (see
  // SaturatedFree).
  struct MapHere {
    MapHere() {}  // lo / hi left unset: only the first skip_->others.size() are ever read
    const octomap::OcTreeNode* history = nullptr;
    std::array<const MapNode*, kMaxOthers> lo, hi;
    bool others_cover = false;  // an other contribution's node covers the whole block
  };
  [[nodiscard]] MapHere RootMap() const;

  // Visits the children of a block that is neither wholly free nor wholly unknown.
  // `beams` is what the pyramid said of this block (a superset of every child's beams):
  // voxels are classified from it, only the voxels it leaves undecided look closer.
  // `code`: the block's Morton code (MortonOf(key_min)), carried down rather than recomputed.
  void VisitChildren(unsigned depth, const std::array<int, 3>& key_min, std::uint64_t code,
                     const Aggregate& beams, bool free_through, const MapHere& map);

  // A mixed block of kShareDepth left to a descent thread: what VisitChildren needs of it, and
  // where its nodes go among the ones decided above it.
  struct Task {
    unsigned depth;
    std::array<int, 3> key_min;
    std::uint64_t code;
    Aggregate beams;
    bool free_through;
    MapHere map;
    std::size_t emitted_before;  // nodes appended to out_ before this block's
    std::size_t worker = 0;      // the thread that visited it, and its nodes there
    std::size_t begin = 0, end = 0;
  };
  // VisitChildren on a task's block (the root's, or one shared out).
  [[gnu::noinline]] void Visit(const Task& task) {
    VisitChildren(task.depth, task.key_min, task.code, task.beams, task.free_through, task.map);
  }
  // The root's task.
  [[nodiscard]] Task Root() const {
    Aggregate everything;
    everything.touched = everything.beams = 1;
    return {0, {0, 0, 0}, 0, everything, /*free_through=*/false, RootMap(), 0};
  }
  // Out of line, as the vector's growth is rare (kept out of VisitChildren's body).
  [[gnu::noinline]] void LeaveTask(const Task& task) { tasks_->push_back(task); }
  // From now on the mixed blocks of kShareDepth are not visited but appended to *tasks.
  void LeaveBlocksTo(std::vector<Task>* tasks) { tasks_ = tasks; }
  // The same descent for another thread: its own centre lines, nodes and counters.
  [[nodiscard]] Descent Fork(DescentBuffers::Directions* directions, RenderedGrid* out,
                             RenderStats* stats) const {
    Descent fork(*this);
    fork.dirs_ = directions;
    fork.directions_ready_ = false;
    fork.out_ = out;
    fork.stats_ = stats;
    fork.tasks_ = nullptr;
    return fork;
  }

 private:
  enum class Kind { kUnknown, kFree, kMixed };
  using Box = BlockBox;

  // Tangent bounds of the field of view, each side moved in by `inset` beam widths.
  struct TanBounds {
    double az_min, az_max, el_min, el_max;
    [[nodiscard]] bool Overlaps(const Box& b) const {
      return b.az_hi >= az_min && b.az_lo <= az_max && b.el_hi >= el_min && b.el_lo <= el_max;
    }
    [[nodiscard]] bool Holds(const Box& b) const {
      return b.az_lo >= az_min && b.az_hi <= az_max && b.el_lo >= el_min && b.el_hi <= el_max;
    }
    [[nodiscard]] bool Holds(double az, double el) const {
      return az >= az_min && az <= az_max && el >= el_min && el <= el_max;
    }
  };

  struct Verdict {
    Kind kind = Kind::kUnknown;
    float free_value = 0.0f;
    bool free_through = false;  // mixed only by geometry: every beam is free through the box
    Aggregate beams;
  };

  MapHere ChildMap(const MapHere& map, unsigned depth, std::uint64_t code, int child,
                   std::array<const MapNode*, kMaxOthers>* next) const;
  // The history holds the whole block at or below the free clamp, and no other live
  // contribution says anything there.
  [[nodiscard]] bool Saturated(const MapHere& m) const;
  // A ray crossed a voxel of the block (its Morton code, its depth) in a beam's first-hit mass
  // with occupied evidence.
  [[nodiscard]] bool HoldsTracedOccupied(std::uint64_t code, unsigned depth) const;
  [[nodiscard]] TanBounds Bounds(double inset) const;
  // The known region that applies at the near / far end of a box.
  [[nodiscard]] const TanBounds& KnownAt(double r2) const {
    return r2 > r_split2_ ? known_far_ : known_near_;
  }
  Verdict Classify(unsigned depth, Box& box, const Aggregate& parent, bool free_through) const;
  // A voxel the pyramid could not decide: its traced value if a ray crossed it in a beam's
  // mass, else free if a beam whose rays reach it is free into it, else unknown. A beam's rays
  // reach the voxel if its centre line does (its direction lies in the voxel's angular box);
  // beyond r_split, where beams are wider than voxels and traced with sub-rays, if the voxel
  // overlaps its sector.
  void VisitVoxel(const std::array<int, 3>& key_min, std::uint64_t code, const Box& box,
                  const Verdict& v, bool saturated);
  // The touched beams among columns [c0, c1) and rows [r0, r1) if the centre line of one of
  // them that is free into the box crosses it (a slab test: the angular box also holds
  // directions that miss a cube at its corners); else nothing.
  Aggregate CentreLinesThrough(const Box& box, int c0, int c1, int r0, int r1);
  // A beam's centre line in the world frame, computed once per render when first needed.
  const Eigen::Vector3f& WorldDirection(std::size_t beam);
  void Emit(unsigned depth, std::uint64_t code, float value);

  const BeamTessellation& tess_;
  const SaturatedFree* skip_;
  const RenderOptions& options_;
  const BeamPyramid& pyramid_;
  const LocalGrid& traced_;
  Eigen::Matrix3d R_;
  Eigen::Matrix3d Rt_;
  Eigen::Vector3d origin_;
  double t_start_;
  double global_far_;
  RenderedGrid* out_;
  RenderStats* stats_;
  double cone2_ = 0.0;  // squared
  TanBounds fov_{}, known_near_{}, known_far_{};
  std::vector<double> col_centres_;  // tangent of each column's centre azimuth, ascending
  std::vector<double> row_centres_;  // tangent of each row's centre elevation, descending
  DescentBuffers::Directions* dirs_;
  const std::vector<std::uint64_t>& occupied_codes_;  // filled where the map may be saturated
  bool directions_ready_ = false;                     // dirs_->have cleared for this render
  std::vector<Task>* tasks_ = nullptr;
  double r_split2_ = 0.0;
  double t_start2_ = 0.0;
  double global_far2_ = 0.0;
};

}  // namespace

#ifdef FUSION_COUNT
// Blocks visited per depth, verdict and free_through (a profiling aid, off by default).
std::size_t g_counts[17][3][2];
#endif

// The members are defined inline, as they would be inside the class: VisitChildren recurses, and
// without the hint the compiler calls its steps instead of inlining them (~10 % more
// instructions per render, measured with callgrind on bench_map). Classify is flattened (and
// the tessellation's look-ups always inlined) for the same reason: with the code that shares the
// descent out in this file the compiler called the pyramid's Query and the look-ups instead
// (88.68 M instead of 83.03 M instructions in the descent of one SR-3000 frame at 5 cm; making
// Visit and LeaveTask out of line alone changed nothing).
inline Descent::Descent(const BeamGrid& grid, const Eigen::Isometry3d& T_world_sensor,
                        const RenderOptions& options, const BeamPyramid& pyramid,
                        const LocalGrid& traced, double t_start, float global_far,
                        const SaturatedFree* skip, DescentBuffers* buffers, RenderedGrid* out,
                        RenderStats* stats)
    : tess_(grid.tessellation()),
      skip_(skip != nullptr && skip->history != nullptr && skip->others.size() <= kMaxOthers
                ? skip
                : nullptr),
      options_(options),
      pyramid_(pyramid),
      traced_(traced),
      R_(T_world_sensor.linear()),
      Rt_(T_world_sensor.linear().transpose()),
      origin_(T_world_sensor.translation()),
      t_start_(t_start),
      global_far_(global_far),
      out_(out),
      stats_(stats),
      dirs_(&buffers->directions.at(0)),
      occupied_codes_(buffers->occupied_codes) {
  // Known space ends where the outermost rays of the ray-traced render run: the centre lines of
  // the edge beams, and beyond r_split (where beams outgrow a voxel) their outermost sub-rays,
  // 1 / (2 k) of a beam from the edge of the field of view.
  fov_ = Bounds(0.0);
  const double width = std::max(tess_.beam_width_h_rad(), tess_.beam_width_v_rad());
  r_split2_ = Square(options.resolution_m / width);
  const int k_far =
      std::clamp(static_cast<int>(std::ceil(width * grid.cells_per_beam() *
                                            grid.options().cell_size_m / options.resolution_m)),
                 1, std::max(1, options.max_subrays_per_axis));
  known_near_ = Bounds(0.5);
  known_far_ = Bounds(0.5 / k_far);
  for (int c = 0; c < tess_.cols(); ++c) col_centres_.push_back(tess_.ColumnCentreTangent(c));
  for (int r = 0; r < tess_.rows(); ++r) row_centres_.push_back(tess_.RowCentreTangent(r));
  // Every direction of the field of view has z >= cone_ * |p| (its corners lean the most).
  const double ta = std::max(std::abs(tess_.TanAzimuthMin()), std::abs(tess_.TanAzimuthMax()));
  const double te = std::max(std::abs(tess_.TanElevationMin()), std::abs(tess_.TanElevationMax()));
  cone2_ = 1.0 / (1.0 + ta * ta + te * te * (1.0 + ta * ta));
  t_start2_ = t_start_ * t_start_;
  global_far2_ = Square(global_far_);
  std::vector<std::uint64_t>& codes = buffers->occupied_codes;
  codes.clear();
  if (skip_ != nullptr) {
    traced.ForEachLogOdds([&codes](const octomap::OcTreeKey& key, float log_odds) {
      if (log_odds > 0.0f) codes.push_back(MortonOf(key));
    });
    std::sort(codes.begin(), codes.end());
  }
}

inline void Descent::VisitChildren(unsigned depth, const std::array<int, 3>& key_min,
                                   std::uint64_t code, const Aggregate& beams, bool free_through,
                                   const MapHere& map) {
  const unsigned child_depth = depth + 1;
  const int half = 1 << (kTreeDepth - child_depth);
  const double res = options_.resolution_m;
  const double child_size = res * half;
  const std::uint64_t span = MortonSpan(child_depth);
  Eigen::Vector3d lo;
  for (int a = 0; a < 3; ++a) lo[a] = (key_min[a] - kMapKeyOffset) * res;
  F4 point[kLatticePoints];
  CornerAngles(Rt_, origin_, lo, child_size, tess_.pinhole(), point);
  double near2[3][2], far2[3][2];
  SlabDistances(origin_, lo, child_size, near2, far2);
  std::array<const MapNode*, kMaxOthers> next;
  std::copy_n(map.lo.begin(), skip_ != nullptr ? skip_->others.size() : 0, next.begin());
  for (int child = 0; child < 8; ++child) {
    const int cx = child & 1, cy = (child >> 1) & 1, cz = (child >> 2) & 1;
    const MapHere child_map = ChildMap(map, depth, code, child, &next);
    const std::array<int, 3> k = {key_min[0] + cx * half, key_min[1] + cy * half,
                                  key_min[2] + cz * half};
    const std::uint64_t child_code = code + static_cast<std::uint64_t>(child) * span;
    // Where the map holds the child free at the clamp, it emits nothing but voxels a ray crossed
    // with occupied evidence: under a parent free through every beam it is free, free through
    // or unknown, and a voxel without such evidence is free at most (VisitVoxel). Its geometry
    // is then not needed.
    const bool saturated = Saturated(child_map);
    if (saturated && (free_through || !HoldsTracedOccupied(child_code, child_depth))) {
      ++stats_->skipped_saturated;
      continue;
    }
    Box box;
    box.size = child_size;
    box.lo = lo + Eigen::Vector3d(cx, cy, cz) * child_size;
    box.r_lo2 = near2[0][cx] + near2[1][cy] + near2[2][cz];
    box.r_hi2 = far2[0][cx] + far2[1][cy] + far2[2][cz];
    if (box.r_hi2 <= t_start2_ || box.r_lo2 >= global_far2_) continue;
    ChildAngles(point, child, &box);
    const Verdict v = Classify(child_depth, box, beams, free_through);
    if (saturated && (v.kind == Kind::kFree || (v.kind == Kind::kMixed && v.free_through))) {
      ++stats_->skipped_saturated;
      continue;  // free where the map is held free at the clamp already
    }
#ifdef FUSION_COUNT
    ++g_counts[child_depth][int(v.kind)][free_through ? 1 : 0];
#endif
    if (v.kind == Kind::kUnknown) continue;
    if (v.kind == Kind::kFree) {
      Emit(child_depth, child_code, v.free_value);
    } else if (child_depth == kTreeDepth) {
      VisitVoxel(k, child_code, box, v, saturated);
    } else if (child_depth == kShareDepth && tasks_ != nullptr) {
      LeaveTask({child_depth, k, child_code, v.beams, v.free_through, child_map, out_->size()});
    } else {
      VisitChildren(child_depth, k, child_code, v.beams, v.free_through, child_map);
    }
  }
}

inline Descent::MapHere Descent::RootMap() const {
  MapHere m;
  if (skip_ == nullptr) return m;
  m.history = skip_->history->getRoot();
  for (std::size_t i = 0; i < skip_->others.size(); ++i) {
    const auto& nodes = skip_->others[i]->nodes();
    m.lo[i] = nodes.data();
    m.hi[i] = nodes.data() + nodes.size();
    if (!nodes.empty() && nodes.front().depth == 0) m.others_cover = true;
  }
  return m;
}

inline Descent::MapHere Descent::ChildMap(const MapHere& map, unsigned depth, std::uint64_t code,
                                          int child,
                                          std::array<const MapNode*, kMaxOthers>* next) const {
  MapHere c;
  if (skip_ == nullptr) return c;
  const octomap::OcTree& tree = *skip_->history;
  if (map.history != nullptr) {
    if (!tree.nodeHasChildren(map.history)) {
      c.history = map.history;  // a coarser leaf holds the child
    } else if (tree.nodeChildExists(map.history, static_cast<unsigned>(child))) {
      c.history = tree.getNodeChild(map.history, static_cast<unsigned>(child));
    }
  }
  c.others_cover = map.others_cover;
  if (c.others_cover || skip_->others.empty()) return c;
  const std::uint64_t end = code + (child + 1) * MortonSpan(depth + 1);
  for (std::size_t i = 0; i < skip_->others.size(); ++i) {
    const MapNode* lo = (*next)[i];
    const MapNode* hi =
        map.hi[i] - lo <= 16
            ? std::find_if(lo, map.hi[i], [end](const MapNode& n) { return n.code >= end; })
            : std::lower_bound(lo, map.hi[i], end,
                               [](const MapNode& n, std::uint64_t e) { return n.code < e; });
    (*next)[i] = hi;
    c.lo[i] = lo;
    c.hi[i] = hi;
    if (lo != hi && lo->depth <= depth + 1) c.others_cover = true;
  }
  return c;
}

inline bool Descent::Saturated(const MapHere& m) const {
  if (skip_ == nullptr || m.history == nullptr || m.others_cover) return false;
  if (skip_->history->nodeHasChildren(m.history) ||
      m.history->getLogOdds() > skip_->clamp_min_log_odds) {
    return false;
  }
  for (std::size_t i = 0; i < skip_->others.size(); ++i) {
    if (m.lo[i] != m.hi[i]) return false;
  }
  return true;
}

inline bool Descent::HoldsTracedOccupied(std::uint64_t code, unsigned depth) const {
  const auto it = std::lower_bound(occupied_codes_.begin(), occupied_codes_.end(), code);
  return it != occupied_codes_.end() && *it < code + MortonSpan(depth);
}

inline Descent::TanBounds Descent::Bounds(double inset) const {
  // The field of view ends where the touched beams do (BeamPyramid::touched_extent).
  const BeamExtent& e = pyramid_.touched_extent();
  const BeamTessellation::TangentBounds b =
      e.empty() ? tess_.InsetTangents(inset)
                : tess_.InsetTangents(inset, e.col_lo, e.col_hi, e.row_lo, e.row_hi);
  return {b.az_min, b.az_max, b.el_min, b.el_max};
}

[[gnu::flatten]] inline Descent::Verdict Descent::Classify(unsigned depth, Box& box,
                                                           const Aggregate& parent,
                                                           bool free_through) const {
  Verdict v;
  const bool voxel = depth == kTreeDepth;
  // Outside the cone that holds the field of view.
  if (box.z_max < 0.0 || box.z_max * box.z_max < cone2_ * box.r_lo2) return v;
  // Near the sensor (or behind its image plane) the corners do not bound the angles.
  if (box.r_lo2 < 4.0 * box.size * box.size || !box.ahead) {
    if (!voxel) v.kind = Kind::kMixed;
    return v;
  }
  // Exact for azimuth (x / z is linear fractional: its extremes are at corners) and for a
  // pinhole grid's -y / z; the elevation tangent may peak inside a face, by at most
  // size^2 / (2 r_lo^2) radians.
  const double margin = tess_.pinhole() ? 0.0 : box.size * box.size / (2.0 * box.r_lo2);
  box.el_lo -= margin * (1.0 + box.el_lo * box.el_lo);
  box.el_hi += margin * (1.0 + box.el_hi * box.el_hi);
  if (!fov_.Overlaps(box)) return v;
  const bool in_known = KnownAt(box.r_lo2).Holds(box) && KnownAt(box.r_hi2).Holds(box);
  if (free_through || voxel) {
    v.beams = parent;
    if (v.beams.touched == 0 || box.r_lo2 >= Square(v.beams.max_far)) return v;
  } else {
    v.beams = pyramid_.Query(tess_.ColumnOfTangent(box.az_lo), tess_.ColumnOfTangent(box.az_hi),
                             tess_.RowOfTangent(box.el_hi), tess_.RowOfTangent(box.el_lo));
    if (v.beams.touched == 0 || box.r_lo2 >= Square(v.beams.max_far)) return v;
  }
  const bool all_free =
      v.beams.touched == v.beams.beams && box.r_hi2 <= Square(v.beams.min_free_end);
  if (all_free && in_known && box.r_lo2 >= t_start2_) {
    v.kind = Kind::kFree;
    v.free_value = v.beams.max_free_value;
    return v;
  }
  v.kind = Kind::kMixed;
  v.free_through = all_free;
  return v;
}

inline void Descent::VisitVoxel(const std::array<int, 3>& key_min, std::uint64_t code,
                                const Box& box, const Verdict& v, bool saturated) {
  const octomap::OcTreeKey key(static_cast<octomap::key_type>(key_min[0]),
                               static_cast<octomap::key_type>(key_min[1]),
                               static_cast<octomap::key_type>(key_min[2]));
  // A voxel free in every beam it overlaps holds no traced segment.
  if (const auto traced = v.free_through ? std::nullopt : traced_.LogOddsOf(key)) {
    if (*traced == 0.0) return;  // crossed, but left unknown (the voxel rule's dead band)
    if (saturated && *traced <= 0.0) {
      ++stats_->skipped_saturated;
    } else {
      Emit(kTreeDepth, code, static_cast<float>(*traced));
    }
    return;
  }
  if (saturated) {  // free at most, where the map holds free at the clamp already
    ++stats_->skipped_saturated;
    return;
  }
  if (!KnownAt(box.r_hi2).Overlaps(box) || box.r_hi2 <= t_start2_) return;
  Aggregate reach;
  if (box.r_hi2 > r_split2_) {
    reach = pyramid_.Query(tess_.ColumnOfTangent(box.az_lo), tess_.ColumnOfTangent(box.az_hi),
                           tess_.RowOfTangent(box.el_hi), tess_.RowOfTangent(box.el_lo));
  } else {
    // The beams whose centre direction lies in the box: the beams holding its corners, less an
    // edge beam whose centre lies outside.
    int c0 = tess_.ColumnOfTangent(box.az_lo), c1 = tess_.ColumnOfTangent(box.az_hi);
    int r0 = tess_.RowOfTangent(box.el_hi), r1 = tess_.RowOfTangent(box.el_lo);
    if (col_centres_[c0] < box.az_lo) ++c0;
    if (col_centres_[c1] > box.az_hi) --c1;
    if (row_centres_[r0] > box.el_hi) ++r0;  // row centres fall with the row index
    if (row_centres_[r1] < box.el_lo) --r1;
    reach = CentreLinesThrough(box, c0, c1 + 1, r0, r1 + 1);
  }
  if (reach.touched != 0 && box.r_lo2 < Square(reach.max_free_end)) {
    Emit(kTreeDepth, code, reach.max_free_value);
  }
}

inline Aggregate Descent::CentreLinesThrough(const Box& box, int c0, int c1, int r0, int r1) {
  Aggregate out;
  if (c1 <= c0 || r1 <= r0) return out;
  const Aggregate all = pyramid_.Query(c0, c1 - 1, r0, r1 - 1);
  if (all.touched == 0 || box.r_lo2 >= Square(all.max_free_end)) return out;
  const Eigen::Vector3d lo = box.lo - origin_;
  const Eigen::Vector3d hi = lo + Eigen::Vector3d::Constant(box.size);
  const auto crosses = [&](int c, int r) {
    const Aggregate& beam = pyramid_.Beam(c, r);
    if (beam.touched == 0 || box.r_lo2 >= Square(beam.max_free_end)) return false;
    const Eigen::Vector3f& d = WorldDirection(static_cast<std::size_t>(r) * tess_.cols() + c);
    double t_in = 0.0, t_out = std::numeric_limits<double>::infinity();
    for (int a = 0; a < 3 && t_in <= t_out; ++a) {
      if (d[a] == 0.0f) {
        if (lo[a] > 0.0 || hi[a] < 0.0) return false;
        continue;
      }
      const double ta = lo[a] / d[a], tb = hi[a] / d[a];
      t_in = std::max(t_in, std::min(ta, tb));
      t_out = std::min(t_out, std::max(ta, tb));
    }
    return t_in <= t_out;
  };
  // The middle beam's line is the likeliest to cross.
  if (crosses((c0 + c1 - 1) / 2, (r0 + r1 - 1) / 2)) return all;
  for (int r = r0; r < r1; ++r) {
    for (int c = c0; c < c1; ++c) {
      if (crosses(c, r)) return all;
    }
  }
  return out;
}

inline const Eigen::Vector3f& Descent::WorldDirection(std::size_t beam) {
  if (!directions_ready_) {
    dirs_->directions.resize(tess_.beam_count());
    dirs_->have.assign(tess_.beam_count(), 0);
    directions_ready_ = true;
  }
  if (dirs_->have[beam] == 0) {
    dirs_->directions[beam] = (R_ * tess_.Direction(beam)).cast<float>();
    dirs_->have[beam] = 1;
  }
  return dirs_->directions[beam];
}

inline void Descent::Emit(unsigned depth, std::uint64_t code, float value) {
  out_->Append({code, value, static_cast<std::uint8_t>(depth)});
  if (depth == kTreeDepth) {
    ++stats_->fine_voxels;
  } else {
    ++stats_->coarse_nodes;
  }
}

namespace {

// The tasks' blocks visited by `workers` threads, each taking the next block left; their nodes
// then put in order among the ones decided above them (`above`) into *out.
void VisitShared(const Descent& descent, std::vector<Descent::Task>* tasks,
                 const RenderedGrid& above, std::size_t workers, DescentBuffers* buffers,
                 RenderedGrid* out, RenderStats* stats) {
  std::vector<RenderedGrid> parts;
  for (std::size_t t = 0; t < workers; ++t) {
    parts.emplace_back(out->resolution_m(), std::move(buffers->nodes[t]));
  }
  std::vector<RenderStats> part_stats(workers);
  std::atomic<std::size_t> next{0};
  RunWorkers(workers, [&](std::size_t t) {
    Descent mine = descent.Fork(&buffers->directions[t], &parts[t], &part_stats[t]);
    for (std::size_t i = next++; i < tasks->size(); i = next++) {
      Descent::Task& task = (*tasks)[i];
      task.worker = t;
      task.begin = parts[t].size();
      mine.Visit(task);
      task.end = parts[t].size();
    }
  });
  std::size_t from = 0;
  for (const Descent::Task& task : *tasks) {
    for (; from < task.emitted_before; ++from) out->Append(above.nodes()[from]);
    const std::vector<MapNode>& nodes = parts[task.worker].nodes();
    for (std::size_t j = task.begin; j < task.end; ++j) out->Append(nodes[j]);
  }
  for (; from < above.size(); ++from) out->Append(above.nodes()[from]);
  for (std::size_t t = 0; t < workers; ++t) {
    stats->coarse_nodes += part_stats[t].coarse_nodes;
    stats->fine_voxels += part_stats[t].fine_voxels;
    stats->skipped_saturated += part_stats[t].skipped_saturated;
    buffers->nodes[t] = parts[t].TakeStorage();
  }
}

}  // namespace

void DescendOctree(const BeamGrid& grid, const Eigen::Isometry3d& T_world_sensor,
                   const RenderOptions& options, const BeamPyramid& pyramid,
                   const LocalGrid& traced, double t_start, float global_far,
                   const SaturatedFree* skip, std::size_t workers, DescentBuffers* buffers,
                   RenderedGrid* out, RenderStats* stats) {
  workers = std::max<std::size_t>(workers, 1);
  if (buffers->directions.size() < workers) buffers->directions.resize(workers);
  Descent descent(grid, T_world_sensor, options, pyramid, traced, t_start, global_far, skip,
                  buffers, out, stats);
  if (workers == 1) {
    descent.Visit(descent.Root());
    return;
  }
  // The coarse levels on this thread, into `above`; the mixed blocks of kShareDepth shared out.
  if (buffers->nodes.size() < workers + 1) buffers->nodes.resize(workers + 1);
  RenderedGrid above(options.resolution_m, std::move(buffers->nodes[workers]));
  std::vector<Descent::Task> tasks;
  Descent top = descent.Fork(&buffers->directions[0], &above, stats);
  top.LeaveBlocksTo(&tasks);
  top.Visit(top.Root());
  VisitShared(descent, &tasks, above, workers, buffers, out, stats);
  buffers->nodes[workers] = above.TakeStorage();
}

}  // namespace fusion::detail
