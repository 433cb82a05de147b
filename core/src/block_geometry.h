// Internal to core (the projective render's octree descent): the geometry of a block's eight
// children as the sensor sees them. Their 27 corners form a 3 x 3 x 3 lattice whose angles are
// taken once for all eight, in floats four at a time (the margins cover the rounding); each
// child's angular box is then the lane-wise minimum and maximum of its eight corners. Inline:
// the descent calls these for every block it visits.
#pragma once

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>

namespace fusion::detail {

// Four floats (SSE on x86-64, NEON on arm64).
using F4 = float __attribute__((vector_size(16)));

// Float rounding of the lattice's tangents, covered by widening every box by this.
inline constexpr double kTanEps = 1e-5;

// Lattice indices (i, j, k) of the 27 corners of a block's eight children, point n = i + 3 j +
// 9 k, four at a time (the 28th repeats the origin).
inline constexpr F4 kLatticeI[7] = {{0, 1, 2, 0}, {1, 2, 0, 1}, {2, 0, 1, 2}, {0, 1, 2, 0},
                                    {1, 2, 0, 1}, {2, 0, 1, 2}, {0, 1, 2, 0}};
inline constexpr F4 kLatticeJ[7] = {{0, 0, 0, 1}, {1, 1, 2, 2}, {2, 0, 0, 0}, {1, 1, 1, 2},
                                    {2, 2, 0, 0}, {0, 1, 1, 1}, {2, 2, 2, 0}};
// The lattice points (i + 3 j + 9 k) at the corners of each child (child c: i, j, k offsets from
// its bits).
inline constexpr int kChildCorners[8][8] = {
    {0, 1, 3, 4, 9, 10, 12, 13},      {1, 2, 4, 5, 10, 11, 13, 14},
    {3, 4, 6, 7, 12, 13, 15, 16},     {4, 5, 7, 8, 13, 14, 16, 17},
    {9, 10, 12, 13, 18, 19, 21, 22},  {10, 11, 13, 14, 19, 20, 22, 23},
    {12, 13, 15, 16, 21, 22, 24, 25}, {13, 14, 16, 17, 22, 23, 25, 26}};
inline constexpr F4 kLatticeK[7] = {{0, 0, 0, 0}, {0, 0, 0, 0}, {0, 1, 1, 1}, {1, 1, 1, 1},
                                    {1, 1, 2, 2}, {2, 2, 2, 2}, {2, 2, 2, 0}};

// One child block as the descent classifies it.
struct BlockBox {
  double size = 0.0;
  Eigen::Vector3d lo = Eigen::Vector3d::Zero();  // world frame, the corner nearest -infinity
  double r_lo2 = 0.0;  // squared distance of the nearest point to the sensor
  double r_hi2 = 0.0;  // squared distance of the farthest corner
  bool ahead = false;  // every corner in front of the sensor
  double z_max = 0.0;  // along the optical axis
  double az_lo = 0.0, az_hi = 0.0, el_lo = 0.0, el_hi = 0.0;  // tangents over the corners
};

// Lattice points CornerAngles writes: the 27 corners and a 28th (the origin's again), so that
// they come four at a time.
inline constexpr int kLatticePoints = 28;

// The 27 corners of the eight children of the block whose corner nearest -infinity is lo (world
// frame), each child child_size wide, in the frame of a sensor at `origin` (world frame):
// per corner {azimuth tangent, elevation tangent's signed square, z, -z}. The elevation tangent
// is -y / hypot(x, z), or -y / z where `over_z` (a pinhole grid's row coordinate).
inline void CornerAngles(const Eigen::Matrix3d& R_sensor_world, const Eigen::Vector3d& origin,
                         const Eigen::Vector3d& lo, double child_size, bool over_z,
                         F4 point[kLatticePoints]) {
  // Corners of the eight children: a 3 x 3 x 3 lattice, its angles in the sensor frame, in
  // floats so that the loop below runs on vectors (the margins cover the rounding).
  const Eigen::Vector3d base = R_sensor_world * (lo - origin);
  const Eigen::Matrix3d step = R_sensor_world * child_size;
  // Azimuth tangent x / z and the elevation tangent's signed square y |y| / (x^2 + z^2) (no
  // square root), four lattice points at a time; each four's {a, e, z, -z} vectors are then
  // transposed into the four points (the lattice is built on vectors too: scalar stores read
  // back as vectors stall).
  const F4 tiny = {1e-6f, 1e-6f, 1e-6f, 1e-6f};
  const F4 one = {1.0f, 1.0f, 1.0f, 1.0f};
  const auto splat = [](double v) {
    const auto f = static_cast<float>(v);
    return F4{f, f, f, f};
  };
  for (int n = 0; n < 28; n += 4) {
    const F4& i = kLatticeI[n / 4];
    const F4& j = kLatticeJ[n / 4];
    const F4& k = kLatticeK[n / 4];
    const F4 x =
        splat(base.x()) + i * splat(step(0, 0)) + j * splat(step(0, 1)) + k * splat(step(0, 2));
    const F4 y =
        splat(base.y()) + i * splat(step(1, 0)) + j * splat(step(1, 1)) + k * splat(step(1, 2));
    const F4 z =
        splat(base.z()) + i * splat(step(2, 0)) + j * splat(step(2, 1)) + k * splat(step(2, 2));
    const F4 zs = z > tiny ? z : one;
    const F4 a = x / zs;
    const F4 ny = -y;
    const F4 e = ny * (ny < 0 ? -ny : ny) / (over_z ? zs * zs : x * x + zs * zs);
    // Per point {azimuth tangent, elevation's signed square, z, -z}: a child's ranges are then
    // the lane-wise minimum and maximum of its eight corners.
    const F4 nz = -z;
    const F4 ae_lo = __builtin_shufflevector(a, e, 0, 4, 1, 5);   // a0 e0 a1 e1
    const F4 zn_lo = __builtin_shufflevector(z, nz, 0, 4, 1, 5);  // z0 -z0 z1 -z1
    const F4 ae_hi = __builtin_shufflevector(a, e, 2, 6, 3, 7);
    const F4 zn_hi = __builtin_shufflevector(z, nz, 2, 6, 3, 7);
    point[n] = __builtin_shufflevector(ae_lo, zn_lo, 0, 1, 4, 5);
    point[n + 1] = __builtin_shufflevector(ae_lo, zn_lo, 2, 3, 6, 7);
    point[n + 2] = __builtin_shufflevector(ae_hi, zn_hi, 0, 1, 4, 5);
    point[n + 3] = __builtin_shufflevector(ae_hi, zn_hi, 2, 3, 6, 7);
  }
}

// Per axis, the nearest and farthest squared distances from the sensor at `origin` of the two
// child slabs.
inline void SlabDistances(const Eigen::Vector3d& origin, const Eigen::Vector3d& lo,
                          double child_size, double near2[3][2], double far2[3][2]) {
  for (int a = 0; a < 3; ++a) {
    for (int c = 0; c < 2; ++c) {
      const double l = lo[a] + c * child_size - origin[a];
      const double h = l + child_size;
      const double n = l > 0.0 ? l : (h < 0.0 ? -h : 0.0);
      const double f = std::max(std::abs(l), std::abs(h));
      near2[a][c] = n * n;
      far2[a][c] = f * f;
    }
  }
}

// A child's angular box (az, el, z_max, ahead) from its eight corners in `point` (CornerAngles).
inline void ChildAngles(const F4 point[kLatticePoints], int child, BlockBox* box) {
  const int* corners = kChildCorners[child];
  F4 lo4 = point[corners[0]], hi4 = lo4;
  for (int c = 1; c < 8; ++c) {
    const F4 q = point[corners[c]];
    lo4 = lo4 < q ? lo4 : q;
    hi4 = hi4 > q ? hi4 : q;
  }
  const float az_lo = lo4[0], el_lo = lo4[1], az_hi = hi4[0], el_hi = hi4[1];
  box->z_max = hi4[2];
  box->ahead = -hi4[3] > 1e-6f;  // the smallest z
  box->az_lo = az_lo - kTanEps;
  box->az_hi = az_hi + kTanEps;
  box->el_lo = std::copysign(std::sqrt(std::abs(el_lo)), el_lo) - kTanEps;
  box->el_hi = std::copysign(std::sqrt(std::abs(el_hi)), el_hi) + kTanEps;
}

}  // namespace fusion::detail
