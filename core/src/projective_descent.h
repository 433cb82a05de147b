// Internal to core (the projective render): the top-down visit of the octree that decides
// blocks as free, unknown or mixed from the beam pyramid, emits the free ones whole and looks
// closer only at the mixed ones, down to the voxels the rays were traced through.
#pragma once

#include <octomap/OcTree.h>

#include <Eigen/Geometry>
#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "beam_pyramid.h"
#include "fusion/core/beam_grid.h"
#include "fusion/core/local_grid.h"
#include "fusion/core/projective_render.h"
#include "fusion/core/rendered_grid.h"

namespace fusion::detail {

// A block whose beams (the pyramid's superset of them) are all touched and free through it, but
// which is not wholly inside the field of view or beyond r_min, passes that verdict down: its
// parts are then decided by geometry alone.
class Descent {
 public:
  // pyramid: every beam's Aggregate; traced: the voxels the rays crossed in the beams' first-hit
  // mass; t_start: where every ray starts; global_far: the largest Aggregate::max_far.
  Descent(const BeamGrid& grid, const Eigen::Isometry3d& T_world_sensor,
          const RenderOptions& options, const BeamPyramid& pyramid, const LocalGrid& traced,
          double t_start, float global_far, const SaturatedFree* skip, RenderedGrid* out,
          RenderStats* stats);

  // The map's history over a block, and the other live contributions' nodes in it (see
  // SaturatedFree).
  struct MapHere {
    const octomap::OcTreeNode* history = nullptr;
    std::array<const MapNode*, 8> lo{}, hi{};
    bool others_cover = false;  // an other contribution's node covers the whole block
  };
  [[nodiscard]] MapHere RootMap() const;

  // Visits the children of a block that is neither wholly free nor wholly unknown.
  // `beams` is what the pyramid said of this block (a superset of every child's beams):
  // voxels are classified from it, only the voxels it leaves undecided look closer.
  void VisitChildren(unsigned depth, const std::array<int, 3>& key_min, const Aggregate& beams,
                     bool free_through, const MapHere& map);

 private:
  enum class Kind { kUnknown, kFree, kMixed };
  struct Box {
    double size = 0.0;
    Eigen::Vector3d lo = Eigen::Vector3d::Zero();  // world frame, the corner nearest -infinity
    double r_lo2 = 0.0;  // squared distance of the nearest point to the sensor
    double r_hi2 = 0.0;  // squared distance of the farthest corner
    bool ahead = false;  // every corner in front of the sensor
    double z_max = 0.0;  // along the optical axis
    double az_lo = 0.0, az_hi = 0.0, el_lo = 0.0, el_hi = 0.0;  // tangents over the corners
  };
  static constexpr std::size_t kMaxOthers = 8;

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

  // Four floats (SSE on x86-64, NEON on arm64): the corner loops below run on vectors.
  using F4 = float __attribute__((vector_size(16)));
  // The 27 corners of the eight children of the block whose corner nearest -infinity is lo
  // (world frame), each child child_size wide, in the sensor frame: per corner {azimuth
  // tangent, elevation tangent's signed square, z, -z}.
  void CornerAngles(const Eigen::Vector3d& lo, double child_size, F4 point[27]) const;
  // Per axis, the nearest and farthest squared distances from the sensor of the two child slabs.
  void SlabDistances(const Eigen::Vector3d& lo, double child_size, double near2[3][2],
                     double far2[3][2]) const;
  // A child's angular box (az, el, z_max, ahead) from its eight corners.
  static void ChildAngles(const F4 point[27], int child, Box* box);
  MapHere ChildMap(const MapHere& map, unsigned depth, const std::array<int, 3>& key_min, int child,
                   std::array<const MapNode*, 8>* next) const;
  // The history holds the whole block at or below the free clamp, and no other live
  // contribution says anything there.
  [[nodiscard]] bool Saturated(const MapHere& m) const;
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
  void VisitVoxel(const std::array<int, 3>& key_min, const Box& box, const Verdict& v,
                  bool saturated);
  // The touched beams among columns [c0, c1) and rows [r0, r1) if the centre line of one of
  // them that is free into the box crosses it (a slab test: the angular box also holds
  // directions that miss a cube at its corners); else nothing.
  Aggregate CentreLinesThrough(const Box& box, int c0, int c1, int r0, int r1);
  // A beam's centre line in the world frame, computed once per render when first needed.
  const Eigen::Vector3f& WorldDirection(std::size_t beam);
  void Emit(unsigned depth, const std::array<int, 3>& key_min, float value);

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
  std::vector<Eigen::Vector3f> directions_;
  std::vector<std::uint8_t> have_direction_;
  double r_split2_ = 0.0;
  double t_start2_ = 0.0;
  double global_far2_ = 0.0;
};

}  // namespace fusion::detail
