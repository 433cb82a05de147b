#include "fusion/core/planes.h"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>

namespace fusion {
namespace {

constexpr double kPi = 3.14159265358979323846;

struct WeightedPoint {
  Eigen::Vector3d p;
  double w;
  bool claimed = false;  // already supports an accepted plane
};

struct Peak {
  double votes;
  Eigen::Vector3d normal;
  double d;
};

// Weighted total-least-squares plane through the points within `band` of (n,
// d).
bool Refine(const std::vector<WeightedPoint>& points, double band, int iterations,
            Eigen::Vector3d* n, double* d) {
  for (int it = 0; it < iterations; ++it) {
    double w_sum = 0.0;
    Eigen::Vector3d mean = Eigen::Vector3d::Zero();
    for (const auto& wp : points) {
      if (wp.claimed || std::abs(n->dot(wp.p) - *d) > band) continue;
      w_sum += wp.w;
      mean += wp.w * wp.p;
    }
    if (w_sum <= 0.0) return false;
    mean /= w_sum;
    Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
    for (const auto& wp : points) {
      if (wp.claimed || std::abs(n->dot(wp.p) - *d) > band) continue;
      const Eigen::Vector3d q = wp.p - mean;
      cov += wp.w * q * q.transpose();
    }
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> solver(cov);
    Eigen::Vector3d normal = solver.eigenvectors().col(0);
    if (normal.dot(*n) < 0.0) normal = -normal;
    *n = normal.normalized();
    *d = n->dot(mean);
  }
  return true;
}

}  // namespace

Eigen::Vector3d NormalFromAngles(double phi_rad, double theta_rad) {
  return Eigen::Vector3d(std::sin(theta_rad) * std::cos(phi_rad),
                         std::sin(theta_rad) * std::sin(phi_rad), std::cos(theta_rad));
}

Plane CanonicalPlane(const Eigen::Vector3d& normal, double distance_m) {
  Plane plane;
  Eigen::Vector3d n = normal.normalized();
  double d = distance_m;
  if (d < 0.0 || (d == 0.0 && n.z() < 0.0)) {
    n = -n;
    d = -d;
  }
  plane.normal = n;
  plane.distance_m = d;
  plane.theta_rad = std::acos(std::clamp(n.z(), -1.0, 1.0));
  plane.phi_rad = std::atan2(n.y(), n.x());
  return plane;
}

std::vector<Plane> DetectPlanes(const octomap::OcTree& tree, const HoughOptions& options) {
  const double res = tree.getResolution();
  const double band = options.support_distance_m > 0.0 ? options.support_distance_m : 1.5 * res;
  std::vector<WeightedPoint> points;
  double max_norm = 0.0;
  for (auto it = tree.begin_leafs(), end = tree.end_leafs(); it != end; ++it) {
    const double p = it->getOccupancy();
    if (p <= options.min_probability) continue;
    const Eigen::Vector3d c(it.getX(), it.getY(), it.getZ());
    if (options.region && !options.region->contains(c)) continue;
    // A pruned leaf stands for all voxels under it: weight by their count.
    const double size_ratio = it.getSize() / res;
    const double w = p * size_ratio * size_ratio * size_ratio;
    points.push_back({c, w, false});
    max_norm = std::max(max_norm, c.norm());
  }
  if (points.empty()) return {};

  const int n_phi = std::max(1, static_cast<int>(std::ceil(2.0 * kPi / options.phi_bin_rad)));
  const int n_theta = std::max(1, static_cast<int>(std::ceil(kPi / options.theta_bin_rad)));
  const double phi_bin = 2.0 * kPi / n_phi;
  const double theta_bin = kPi / n_theta;
  const int n_d = static_cast<int>(std::floor(max_norm / options.d_bin_m)) + 2;
  const std::size_t n_normals = static_cast<std::size_t>(n_phi) * n_theta;
  std::vector<Eigen::Vector3f> normals(n_normals);
  for (int t = 0; t < n_theta; ++t) {
    for (int f = 0; f < n_phi; ++f) {
      normals[static_cast<std::size_t>(t) * n_phi + f] =
          NormalFromAngles(-kPi + (f + 0.5) * phi_bin, (t + 0.5) * theta_bin).cast<float>();
    }
  }
  // Votes: accumulator[normal][d]. Each voxel votes once per normal with d = n
  // . p >= 0 (the opposite normal takes d < 0).
  std::vector<float> acc(n_normals * static_cast<std::size_t>(n_d), 0.0f);
  const float inv_d_bin = static_cast<float>(1.0 / options.d_bin_m);
  for (const auto& wp : points) {
    const Eigen::Vector3f p = wp.p.cast<float>();
    const auto w = static_cast<float>(wp.w);
    for (std::size_t k = 0; k < n_normals; ++k) {
      const float d = normals[k].dot(p);
      if (d < 0.0f) continue;
      const auto bin = static_cast<std::size_t>(d * inv_d_bin);
      acc[k * n_d + bin] += w;
    }
  }

  // Local maxima over the 3 x 3 x 3 neighbourhood (phi wraps around).
  std::vector<Peak> peaks;
  for (int t = 0; t < n_theta; ++t) {
    for (int f = 0; f < n_phi; ++f) {
      const std::size_t k = static_cast<std::size_t>(t) * n_phi + f;
      for (int b = 0; b < n_d; ++b) {
        const float v = acc[k * n_d + b];
        if (v <= 0.0f) continue;
        bool is_max = true;
        for (int dt = -1; dt <= 1 && is_max; ++dt) {
          const int tt = t + dt;
          if (tt < 0 || tt >= n_theta) continue;
          for (int df = -1; df <= 1 && is_max; ++df) {
            const int ff = (f + df + n_phi) % n_phi;
            const std::size_t kk = static_cast<std::size_t>(tt) * n_phi + ff;
            for (int db = -1; db <= 1; ++db) {
              const int bb = b + db;
              if (bb < 0 || bb >= n_d || (dt == 0 && df == 0 && db == 0)) continue;
              if (acc[kk * n_d + bb] > v) {
                is_max = false;
                break;
              }
            }
          }
        }
        if (is_max) peaks.push_back({v, normals[k].cast<double>(), (b + 0.5) * options.d_bin_m});
      }
    }
  }
  std::sort(peaks.begin(), peaks.end(),
            [](const Peak& a, const Peak& b) { return a.votes > b.votes; });

  const double cos_nms = std::cos(options.nms_angle_rad);
  auto near = [&](const Eigen::Vector3d& n1, double d1, const Eigen::Vector3d& n2, double d2) {
    return (n1.dot(n2) > cos_nms && std::abs(d1 - d2) < options.nms_distance_m) ||
           (-n1.dot(n2) > cos_nms && std::abs(d1 + d2) < options.nms_distance_m);
  };
  std::vector<Plane> planes;
  std::vector<Peak> accepted;
  for (const Peak& peak : peaks) {
    if (planes.size() >= options.max_planes) break;
    bool suppressed = false;
    for (const Peak& a : accepted) suppressed |= near(peak.normal, peak.d, a.normal, a.d);
    for (const Plane& a : planes) suppressed |= near(peak.normal, peak.d, a.normal, a.distance_m);
    if (suppressed) continue;
    accepted.push_back(peak);
    Eigen::Vector3d n = peak.normal;
    double d = peak.d;
    if (!Refine(points, band, options.refine_iterations, &n, &d)) continue;
    Plane plane = CanonicalPlane(n, d);
    plane.extent.setEmpty();
    double sq = 0.0;
    // Support: voxels near the plane not explained by a stronger plane. Without
    // this, planes cutting obliquely through a strong plane's voxels would be
    // reported as well.
    for (const auto& wp : points) {
      const double r = plane.normal.dot(wp.p) - plane.distance_m;
      if (wp.claimed || std::abs(r) > band) continue;
      ++plane.support_voxels;
      plane.votes += wp.w;
      sq += r * r;
      plane.extent.extend(wp.p);
    }
    if (plane.support_voxels < options.min_support_voxels) continue;
    plane.rms_m = std::sqrt(sq / static_cast<double>(plane.support_voxels));
    bool duplicate = false;
    for (const Plane& a : planes) {
      duplicate |= near(plane.normal, plane.distance_m, a.normal, a.distance_m);
    }
    if (duplicate) continue;
    for (auto& wp : points) {
      if (std::abs(plane.normal.dot(wp.p) - plane.distance_m) <= band) wp.claimed = true;
    }
    planes.push_back(plane);
  }
  std::sort(planes.begin(), planes.end(),
            [](const Plane& a, const Plane& b) { return a.votes > b.votes; });
  return planes;
}

}  // namespace fusion
