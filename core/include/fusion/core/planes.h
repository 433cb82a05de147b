// Plane detection on the fused octree (paper Sec. V): a Hough transform over
// (phi, theta, d) voting with the occupancy probability of every leaf (merged into small
// cubes first), peak extraction with non-maximum suppression measured at each plane's
// support, a weighted least-squares refinement on the merged voters and, for the planes
// found, once more on the supporting voxels.
//
// Convention: a plane is {p : n . p = d} in the world frame with d >= 0
// (metres) and unit normal n = (sin(theta) cos(phi), sin(theta) sin(phi),
// cos(theta)), phi in [-pi, pi) the normal's azimuth, theta in [0, pi] its
// polar angle from +z. A plane through the origin keeps the normal with theta
// <= pi/2.
#pragma once

#include <octomap/OcTree.h>

#include <Eigen/Geometry>
#include <cstddef>
#include <functional>
#include <optional>
#include <string>
#include <vector>

namespace fusion {

struct HoughOptions {
  static constexpr double kDegree = 0.017453292519943295;

  double phi_bin_rad = 2.0 * kDegree;
  double theta_bin_rad = 2.0 * kDegree;
  double d_bin_m = 0.02;
  // Leaves at or below this occupancy do not vote.
  double min_probability = 0.5;
  // Only leaves whose centre lies in this box vote (world frame); everything if
  // unset.
  std::optional<Eigen::AlignedBox3d> region;
  std::size_t max_planes = 8;
  // Peaks closer than this to a stronger plane are suppressed: normals within the angle and
  // the peak's plane within the distance of the stronger plane's support (its centroid).
  double nms_angle_rad = 10.0 * kDegree;
  double nms_distance_m = 0.10;
  // A plane needs at least this many supporting voxels after refinement.
  std::size_t min_support_voxels = 50;
  // Voxels within this distance of a peak's plane support it (refinement); 0
  // = 1.5 voxels.
  double support_distance_m = 0.0;
  int refine_iterations = 3;
  // Voters are merged into cubes of this many voxels a side (one voter per cube at its voxels'
  // weighted centroid, their summed weight): a plane's cubes stay on it, and a surface costs
  // ~1 / n^2 of its voxels. Candidates are refined, judged and claim their support on these
  // voters; only the planes found are refined once more on the voxels. 1: every leaf alone.
  int vote_merge_voxels = 4;
  // Coarse to fine when the cubes above are smaller than this (metres; 2 cm maps and finer):
  // every normal is first voted by cubes of twice their edge (a quarter of the votes), then the
  // normals holding at least a quarter of the strongest cell's votes (and their neighbours)
  // are voted again by the cubes above. What a vote costs stops growing as the map gets finer;
  // the peaks of the strong planes are those of the fine vote. 0: one vote by the cubes above.
  double vote_cube_min_m = 0.16;
  // Work bounds. A search whose accumulator (normals x distance bins, plus the normals
  // themselves) would exceed this many cells is refused before it allocates (0 = no bound).
  std::size_t max_accumulator_cells = 0;
  // Polled about every million steps of each loop; the search ends (kStopped) once it
  // returns true. Unset: never stops early.
  std::function<bool()> stop;

  // Bins positive and finite (angles at most pi), min_probability in [0, 1), at least one
  // plane, suppression and support distances finite and >= 0, refine_iterations >= 0,
  // vote_merge_voxels in 1..64, vote_cube_min_m finite in [0, 10], a region finite with
  // min <= max. False with *why (may be null) naming the field.
  [[nodiscard]] bool IsValid(std::string* why = nullptr) const;
};

struct Plane {
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();  // unit, world frame
  double distance_m = 0.0;                            // d >= 0
  double phi_rad = 0.0;
  double theta_rad = 0.0;
  double votes = 0.0;              // sum of p(m) of the supporting voxels
  std::size_t support_voxels = 0;  // voxels within support_distance of the plane
  double rms_m = 0.0;              // RMS distance of the supporting voxel centres
  Eigen::AlignedBox3d extent;      // bounding box of the supporting voxel centres
};

// Normal from the angles and back (see the convention above).
[[nodiscard]] Eigen::Vector3d NormalFromAngles(double phi_rad, double theta_rad);
// Puts (n, d) in canonical form (d >= 0) and fills phi/theta.
[[nodiscard]] Plane CanonicalPlane(const Eigen::Vector3d& normal, double distance_m);
enum class PlaneSearchStatus { kOk, kTooLarge, kStopped };

struct PlaneSearch {
  PlaneSearchStatus status = PlaneSearchStatus::kOk;
  std::vector<Plane> planes;          // sorted by votes, strongest first (kOk only)
  std::size_t voters = 0;             // leaves that voted
  std::size_t accumulator_cells = 0;  // what the search needs (checked against the bound)
};

// The Hough search within the options' bounds.
[[nodiscard]] PlaneSearch SearchPlanes(const octomap::OcTree& tree,
                                       const HoughOptions& options = {});
// Planes sorted by votes, strongest first (SearchPlanes without bounds' outcome).
[[nodiscard]] std::vector<Plane> DetectPlanes(const octomap::OcTree& tree,
                                              const HoughOptions& options = {});

}  // namespace fusion
