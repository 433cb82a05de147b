#include "fusion/core/planes.h"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <stdexcept>
#include <tuple>
#include <unordered_map>

namespace fusion {
namespace {

constexpr double kPi = 3.14159265358979323846;

// A voter: a leaf, or a cube of leaves merged at their weighted centroid.
struct WeightedPoint {
  Eigen::Vector3d p;
  double w;              // its vote: p(m) times the voxels it stands for
  double voxels = 1.0;   // voxels of the finest depth it stands for
  double evidence = 0.0;  // log-odds above the least that votes, times its voxels (voxels only)
  bool claimed = false;  // already supports an accepted plane
};

struct Peak {
  double votes;
  Eigen::Vector3d normal;
  double d;
};

// Weighted total-least-squares plane through the points within `band` of (n, d), weighted by
// their votes or by their evidence.
bool Refine(const std::vector<WeightedPoint>& points, double band, int iterations, bool by_evidence,
            Eigen::Vector3d* n, double* d) {
  const auto weight = [by_evidence](const WeightedPoint& wp) {
    return by_evidence ? wp.evidence : wp.w;
  };
  for (int it = 0; it < iterations; ++it) {
    double w_sum = 0.0;
    Eigen::Vector3d mean = Eigen::Vector3d::Zero();
    for (const auto& wp : points) {
      if (wp.claimed || std::abs(n->dot(wp.p) - *d) > band) continue;
      w_sum += weight(wp);
      mean += weight(wp) * wp.p;
    }
    if (w_sum <= 0.0) return false;
    mean /= w_sum;
    Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
    for (const auto& wp : points) {
      if (wp.claimed || std::abs(n->dot(wp.p) - *d) > band) continue;
      const Eigen::Vector3d q = wp.p - mean;
      cov += weight(wp) * q * q.transpose();
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

namespace {

// Polls options.stop about every kPollWork steps of work.
class Poller {
 public:
  explicit Poller(const std::function<bool()>& stop) : stop_(stop) {}
  bool Tick(std::size_t work) {
    if (stopped_) return true;
    work_ += work;
    if (work_ >= kPollWork) {
      work_ = 0;
      stopped_ = stop_ && stop_();
    }
    return stopped_;
  }
  [[nodiscard]] bool stopped() const { return stopped_; }

 private:
  static constexpr std::size_t kPollWork = std::size_t{1} << 20;
  const std::function<bool()>& stop_;
  std::size_t work_ = 0;
  bool stopped_ = false;
};

// The leaves that vote, weighted by occupancy and by the voxels a pruned leaf stands for.
std::vector<WeightedPoint> CollectVoters(const octomap::OcTree& tree, const HoughOptions& options,
                                         Poller* poller, double* max_norm) {
  const double res = tree.getResolution();
  std::vector<WeightedPoint> points;
  *max_norm = 0.0;
  const double least = std::max(options.min_probability, 1e-6);
  const double min_log_odds = std::log(least / (1.0 - least));
  for (auto it = tree.begin_leafs(), end = tree.end_leafs(); it != end; ++it) {
    if (poller->Tick(16)) break;
    const double p = it->getOccupancy();
    if (p <= options.min_probability) continue;
    const Eigen::Vector3d c(it.getX(), it.getY(), it.getZ());
    if (options.region && !options.region->contains(c)) continue;
    const double size_ratio = it.getSize() / res;
    const double voxels = size_ratio * size_ratio * size_ratio;
    const double evidence = std::max(0.0, static_cast<double>(it->getLogOdds()) - min_log_odds);
    points.push_back({c, p * voxels, voxels, evidence * voxels, false});
    *max_norm = std::max(*max_norm, c.norm());
  }
  return points;
}

// The voters merged into cubes of `cell` metres: one voter per cube at the weighted centroid
// of its voxels, carrying their summed weight. A plane's voxels have their centroid on the
// plane, so the peaks stay where they were while the votes cost a fraction (a surface's voxels
// shrink by the square of the merge factor).
std::vector<WeightedPoint> MergedVoters(const std::vector<WeightedPoint>& points, double cell,
                                        Poller* poller) {
  struct Sum {
    Eigen::Vector3d wp = Eigen::Vector3d::Zero();
    double w = 0.0, voxels = 0.0;
  };
  std::unordered_map<std::uint64_t, Sum> cubes;
  cubes.reserve(points.size() / 4 + 1);
  const double inv = 1.0 / cell;
  for (const auto& wp : points) {
    if (poller->Tick(4)) return {};
    // 21 bits per axis: +-1e6 cubes around the origin (km at metre cubes).
    const auto axis = [inv](double v) {
      return static_cast<std::uint64_t>(static_cast<std::int64_t>(std::floor(v * inv)) +
                                        (std::int64_t{1} << 20)) &
             ((std::uint64_t{1} << 21) - 1);
    };
    Sum& sum = cubes[(axis(wp.p.x()) << 42) | (axis(wp.p.y()) << 21) | axis(wp.p.z())];
    sum.wp += wp.w * wp.p;
    sum.w += wp.w;
    sum.voxels += wp.voxels;
  }
  std::vector<WeightedPoint> merged;
  merged.reserve(cubes.size());
  for (const auto& [key, sum] : cubes) {
    merged.push_back({sum.wp / sum.w, sum.w, sum.voxels, 0.0, false});
  }
  // The hash map's order is not the input's: sort so that the search is deterministic.
  std::sort(merged.begin(), merged.end(), [](const WeightedPoint& a, const WeightedPoint& b) {
    return std::tie(a.p.x(), a.p.y(), a.p.z()) < std::tie(b.p.x(), b.p.y(), b.p.z());
  });
  return merged;
}

// Votes: cells[normal][d]. Each voxel votes once per normal with d = n . p >= 0 (the opposite
// normal takes d < 0).
struct Accumulator {
  int n_phi = 1, n_theta = 1, n_d = 1;
  double d_bin_m = 1.0;
  std::vector<Eigen::Vector3f> normals;
  std::vector<float> cells;

  Accumulator(const HoughOptions& options, double max_norm_m)
      : n_phi(std::max(1, static_cast<int>(std::ceil(2.0 * kPi / options.phi_bin_rad)))),
        n_theta(std::max(1, static_cast<int>(std::ceil(kPi / options.theta_bin_rad)))),
        n_d(static_cast<int>(std::floor(max_norm_m / options.d_bin_m)) + 2),
        d_bin_m(options.d_bin_m) {}
  [[nodiscard]] std::size_t n_normals() const { return std::size_t(n_phi) * std::size_t(n_theta); }
  // Cells to allocate: the votes and the normals (three floats each).
  [[nodiscard]] std::size_t needed_cells() const { return n_normals() * (std::size_t(n_d) + 3); }
  void Allocate() {
    const double phi_bin = 2.0 * kPi / n_phi, theta_bin = kPi / n_theta;
    normals.resize(n_normals());
    for (int t = 0; t < n_theta; ++t) {
      for (int f = 0; f < n_phi; ++f) {
        normals[std::size_t(t) * n_phi + f] =
            NormalFromAngles(-kPi + (f + 0.5) * phi_bin, (t + 0.5) * theta_bin).cast<float>();
      }
    }
    cells.assign(n_normals() * std::size_t(n_d), 0.0f);
  }
  [[nodiscard]] float at(std::size_t k, int b) const { return cells[k * n_d + b]; }
};

// Voters in blocks small enough to stay in cache (coordinates as floats, one array each); each
// block votes normal by normal (the rows listed, all if none), so that one normal's row of
// distance bins takes every vote of the block in turn (voter by voter, every vote would land in
// another row: a cache miss each). Neighbouring voters mostly vote into the same bin: a row is
// summed in kLanes interleaved copies, so that consecutive additions do not wait for each other.
void Vote(const std::vector<WeightedPoint>& points, const std::vector<std::size_t>& rows,
          Accumulator* acc, Poller* poller) {
  constexpr std::size_t kBlock = 8192, kLanes = 4;
  const float inv_d_bin = static_cast<float>(1.0 / acc->d_bin_m);
  const std::size_t n_rows = rows.empty() ? acc->n_normals() : rows.size();
  const std::size_t n_d = static_cast<std::size_t>(acc->n_d);
  std::vector<float> x, y, z, w, lanes(kLanes * n_d);
  for (std::size_t begin = 0; begin < points.size(); begin += kBlock) {
    const std::size_t end = std::min(points.size(), begin + kBlock);
    x.clear(), y.clear(), z.clear(), w.clear();
    for (std::size_t i = begin; i < end; ++i) {
      x.push_back(static_cast<float>(points[i].p.x()));
      y.push_back(static_cast<float>(points[i].p.y()));
      z.push_back(static_cast<float>(points[i].p.z()));
      w.push_back(static_cast<float>(points[i].w));
    }
    for (std::size_t r = 0; r < n_rows; ++r) {
      if (poller->Tick(x.size())) return;
      const std::size_t k = rows.empty() ? r : rows[r];
      const Eigen::Vector3f& n = acc->normals[k];
      std::fill(lanes.begin(), lanes.end(), 0.0f);
      for (std::size_t i = 0; i < x.size(); ++i) {
        // Branch-free: a negative distance adds nothing to bin 0 (half the votes, in no
        // predictable order, would otherwise mispredict).
        const float d = n.x() * x[i] + n.y() * y[i] + n.z() * z[i];
        const bool ahead = d >= 0.0f;
        const auto bin = static_cast<std::uint32_t>((ahead ? d : 0.0f) * inv_d_bin);
        lanes[bin * kLanes + i % kLanes] += ahead ? w[i] : 0.0f;
      }
      float* row = acc->cells.data() + k * n_d;
      for (std::size_t b = 0; b < n_d; ++b) {
        row[b] += (lanes[b * kLanes] + lanes[b * kLanes + 1]) +
                  (lanes[b * kLanes + 2] + lanes[b * kLanes + 3]);
      }
    }
  }
}

// Coarse to fine: the normals (rows) whose strongest cell holds at least kShare of the
// strongest cell's votes, with their 8 neighbours (phi wraps around), cleared for a second vote.
std::vector<std::size_t> ClearStrongRows(Accumulator* acc) {
  constexpr float kShare = 0.25f;
  const std::size_t n_d = static_cast<std::size_t>(acc->n_d);
  std::vector<float> row_max(acc->n_normals(), 0.0f);
  for (std::size_t k = 0; k < row_max.size(); ++k) {
    const float* row = acc->cells.data() + k * n_d;
    row_max[k] = *std::max_element(row, row + n_d);
  }
  const float least = kShare * *std::max_element(row_max.begin(), row_max.end());
  std::vector<bool> strong(row_max.size(), false);
  for (int t = 0; t < acc->n_theta; ++t) {
    for (int f = 0; f < acc->n_phi; ++f) {
      if (row_max[std::size_t(t) * acc->n_phi + f] < least) continue;
      for (int tt = std::max(0, t - 1); tt <= std::min(acc->n_theta - 1, t + 1); ++tt) {
        for (int df = -1; df <= 1; ++df) {
          strong[std::size_t(tt) * acc->n_phi + (f + df + acc->n_phi) % acc->n_phi] = true;
        }
      }
    }
  }
  std::vector<std::size_t> rows;
  for (std::size_t k = 0; k < strong.size(); ++k) {
    if (!strong[k]) continue;
    rows.push_back(k);
    std::fill_n(acc->cells.data() + k * n_d, n_d, 0.0f);
  }
  return rows;
}

// Whether cell (t, f, b) is a maximum of its 3 x 3 x 3 neighbourhood (phi wraps around).
bool IsLocalMax(const Accumulator& acc, int t, int f, int b, float v) {
  for (int dt = -1; dt <= 1; ++dt) {
    const int tt = t + dt;
    if (tt < 0 || tt >= acc.n_theta) continue;
    for (int df = -1; df <= 1; ++df) {
      const std::size_t kk = std::size_t(tt) * acc.n_phi + (f + df + acc.n_phi) % acc.n_phi;
      for (int db = -1; db <= 1; ++db) {
        const int bb = b + db;
        if (bb < 0 || bb >= acc.n_d || (dt == 0 && df == 0 && db == 0)) continue;
        if (acc.at(kk, bb) > v) return false;
      }
    }
  }
  return true;
}

// The strongest local maxima with at least min_votes, strongest first; at most kMaxPeaks are
// kept.
std::vector<Peak> FindPeaks(const Accumulator& acc, float min_votes, Poller* poller) {
  constexpr std::size_t kMaxPeaks = 16384;
  const auto stronger = [](const Peak& a, const Peak& b) { return a.votes > b.votes; };
  std::vector<Peak> peaks;
  const auto trim = [&] {
    if (peaks.size() <= kMaxPeaks) return;
    std::nth_element(peaks.begin(), peaks.begin() + kMaxPeaks, peaks.end(), stronger);
    peaks.resize(kMaxPeaks);
  };
  for (int t = 0; t < acc.n_theta; ++t) {
    for (int f = 0; f < acc.n_phi; ++f) {
      if (poller->Tick(std::size_t(acc.n_d))) return {};
      const std::size_t k = std::size_t(t) * acc.n_phi + f;
      for (int b = 0; b < acc.n_d; ++b) {
        const float v = acc.at(k, b);
        if (v < min_votes || v <= 0.0f || !IsLocalMax(acc, t, f, b, v)) continue;
        peaks.push_back({v, acc.normals[k].cast<double>(), (b + 0.5) * acc.d_bin_m});
        if (peaks.size() >= 2 * kMaxPeaks) trim();
      }
    }
  }
  trim();
  std::sort(peaks.begin(), peaks.end(), stronger);
  return peaks;
}

// Whether a peak's plane, its normal within the angle of an accepted plane's, passes through
// (or within `distance` of) the box of that plane's support: a thick or slightly tilted copy
// of the same surface, which would refine into a strip of it.
bool Crosses(const Peak& peak, const Plane& a, double cos_angle, double distance) {
  if (std::abs(peak.normal.dot(a.normal)) <= cos_angle) return false;
  double lo = std::numeric_limits<double>::infinity(), hi = -lo;
  for (int corner = 0; corner < 8; ++corner) {
    const Eigen::Vector3d c = a.extent.corner(static_cast<Eigen::AlignedBox3d::CornerType>(corner));
    const double r = peak.normal.dot(c) - peak.d;
    lo = std::min(lo, r);
    hi = std::max(hi, r);
  }
  return lo <= distance && hi >= -distance;
}

// Whether `plane` is a stronger accepted plane seen again: a normal within the angle and most
// (by weight) of the voxels within `band` of it, claimed or not, within `distance` of that
// plane. A surface thickened by pose error or noise supports planes tilted a degree or two
// against it; they share its voxels. A parallel surface elsewhere (a table above the floor)
// shares none.
bool DuplicatesOne(const Plane& plane, const std::vector<Plane>& accepted,
                   const std::vector<WeightedPoint>& points, double band, double cos_angle,
                   double distance) {
  std::vector<double> shared(accepted.size(), 0.0);
  std::vector<bool> parallel(accepted.size());
  bool any = false;
  for (std::size_t i = 0; i < accepted.size(); ++i) {
    parallel[i] = std::abs(plane.normal.dot(accepted[i].normal)) > cos_angle;
    any |= parallel[i];
  }
  if (!any) return false;
  double total = 0.0;
  for (const auto& wp : points) {
    if (std::abs(plane.normal.dot(wp.p) - plane.distance_m) > band) continue;
    total += wp.w;
    for (std::size_t i = 0; i < accepted.size(); ++i) {
      const Plane& a = accepted[i];
      if (parallel[i] && std::abs(a.normal.dot(wp.p) - a.distance_m) <= distance) {
        shared[i] += wp.w;
      }
    }
  }
  for (const double w : shared) {
    if (total > 0.0 && w >= 0.5 * total) return true;
  }
  return false;
}

// The plane (n, d) with the statistics of its support: the unclaimed points within `band`
// (their voxels, summed weight, RMS distance of the points, bounding box, weighted centroid).
// A plane that claims nothing is left with support_voxels 0.
Plane SupportOf(const Eigen::Vector3d& n, double d, const std::vector<WeightedPoint>& points,
                double band, Eigen::Vector3d* centroid) {
  Plane plane = CanonicalPlane(n, d);
  plane.extent.setEmpty();
  double sq = 0.0, voxels = 0.0;
  std::size_t count = 0;
  *centroid = Eigen::Vector3d::Zero();
  for (const auto& wp : points) {
    const double r = plane.normal.dot(wp.p) - plane.distance_m;
    if (wp.claimed || std::abs(r) > band) continue;
    ++count;
    voxels += wp.voxels;
    plane.votes += wp.w;
    sq += r * r;
    *centroid += wp.w * wp.p;
    plane.extent.extend(wp.p);
  }
  if (count == 0 || plane.votes <= 0.0) return plane;
  *centroid /= plane.votes;
  plane.support_voxels = static_cast<std::size_t>(std::llround(voxels));
  plane.rms_m = std::sqrt(sq / static_cast<double>(count));
  return plane;
}

// The plane claims its points out to `claim_m`: the rest of a thick surface would otherwise
// refine into copies of it (which DuplicatesOne refuses, one by one).
void Claim(const Plane& plane, double claim_m, std::vector<WeightedPoint>* points) {
  for (auto& wp : *points) {
    if (std::abs(plane.normal.dot(wp.p) - plane.distance_m) <= claim_m) wp.claimed = true;
  }
}

// Peaks refined into planes on the voters, in the order they are accepted (strongest peak
// first), each claiming its supporting voters.
std::vector<Plane> ExtractPlanes(const std::vector<Peak>& peaks, std::vector<WeightedPoint>* points,
                                 const HoughOptions& options, double band, Poller* poller) {
  const double cos_nms = std::cos(options.nms_angle_rad);
  // A candidate (n, d) duplicates an accepted plane when their normals are within the angle
  // and the candidate passes within the distance of the accepted plane's support (its
  // centroid): measured there, not at the world origin, where a 1-degree tilt 4 m away moves d
  // by 7 cm.
  auto near = [&](const Eigen::Vector3d& n, double d, const Plane& a, const Eigen::Vector3d& at) {
    return std::abs(n.dot(a.normal)) > cos_nms &&
           std::abs(n.dot(at) - d) < options.nms_distance_m;
  };
  std::vector<Plane> planes;
  // Every refined candidate with support, accepted or not, and its support's centroid: a later
  // peak near one of them would refine to it again. At most kMaxCandidates are refined.
  std::vector<std::pair<Plane, Eigen::Vector3d>> seen;
  const std::size_t kMaxCandidates = 32 * options.max_planes;
  std::size_t candidates = 0;
  for (const Peak& peak : peaks) {
    if (planes.size() >= options.max_planes || candidates >= kMaxCandidates ||
        poller->Tick(points->size() * 8)) {
      break;
    }
    bool suppressed = false;
    for (const auto& [a, at] : seen) suppressed |= near(peak.normal, peak.d, a, at);
    for (const Plane& a : planes) suppressed |= Crosses(peak, a, cos_nms, options.nms_distance_m);
    if (suppressed) continue;
    ++candidates;
    Eigen::Vector3d n = peak.normal;
    double d = peak.d;
    if (!Refine(*points, band, options.refine_iterations, false, &n, &d)) continue;
    // Support: voters near the plane not explained by a stronger plane. Without this, planes
    // cutting obliquely through a strong plane's voxels would be reported as well.
    Eigen::Vector3d centroid;
    const Plane plane = SupportOf(n, d, *points, band, &centroid);
    if (plane.votes <= 0.0) continue;
    seen.emplace_back(plane, centroid);
    if (plane.support_voxels < options.min_support_voxels) continue;
    if (DuplicatesOne(plane, planes, *points, band, cos_nms, options.nms_distance_m)) continue;
    Claim(plane, std::max(band, options.nms_distance_m), points);
    planes.push_back(plane);
  }
  return planes;
}

// The planes found on the voters, in their order, refined once more on the voxels themselves,
// each claiming its voxels as it did its voters: normal, distance and support statistics come
// from the voxels. The result is sorted by votes, strongest first.
std::vector<Plane> RefineOnVoxels(const std::vector<Plane>& found,
                                  std::vector<WeightedPoint>* voxels, const HoughOptions& options,
                                  double band, Poller* poller) {
  std::vector<Plane> planes;
  for (const Plane& coarse : found) {
    if (poller->Tick(voxels->size() * 8)) break;
    Eigen::Vector3d n = coarse.normal;
    double d = coarse.distance_m;
    if (!Refine(*voxels, band, options.refine_iterations, true, &n, &d)) continue;
    Eigen::Vector3d centroid;
    const Plane plane = SupportOf(n, d, *voxels, band, &centroid);
    if (plane.support_voxels < options.min_support_voxels) continue;
    Claim(plane, std::max(band, options.nms_distance_m), voxels);
    planes.push_back(plane);
  }
  std::sort(planes.begin(), planes.end(),
            [](const Plane& a, const Plane& b) { return a.votes > b.votes; });
  return planes;
}

}  // namespace

bool HoughOptions::IsValid(std::string* why) const {
  const auto fail = [why](const char* message) {
    if (why != nullptr) *why = message;
    return false;
  };
  const auto positive = [](double v, double max) { return v > 0.0 && v <= max; };
  const auto non_negative = [](double v) { return v >= 0.0 && std::isfinite(v); };
  if (!positive(phi_bin_rad, kPi)) return fail("phi_bin_rad must lie in (0, pi]");
  if (!positive(theta_bin_rad, kPi)) return fail("theta_bin_rad must lie in (0, pi]");
  if (!positive(d_bin_m, 1e6)) return fail("d_bin_m must be finite and > 0");
  if (!(min_probability >= 0.0 && min_probability < 1.0)) {
    return fail("min_probability must lie in [0, 1)");
  }
  if (max_planes == 0) return fail("max_planes must be >= 1");
  if (!non_negative(nms_angle_rad)) return fail("nms_angle_rad must be finite and >= 0");
  if (!non_negative(nms_distance_m)) return fail("nms_distance_m must be finite and >= 0");
  if (!non_negative(support_distance_m)) {
    return fail("support_distance_m must be finite and >= 0");
  }
  if (refine_iterations < 0) return fail("refine_iterations must be >= 0");
  if (vote_merge_voxels < 1 || vote_merge_voxels > 64) {
    return fail("vote_merge_voxels must lie in 1..64");
  }
  if (!(vote_cube_min_m >= 0.0 && vote_cube_min_m <= 10.0)) {
    return fail("vote_cube_min_m must lie in [0, 10]");
  }
  if (region && (!region->min().allFinite() || !region->max().allFinite() ||
                 (region->min().array() > region->max().array()).any())) {
    return fail("region must be finite with min <= max");
  }
  return true;
}

PlaneSearch SearchPlanes(const octomap::OcTree& tree, const HoughOptions& options) {
  if (std::string why; !options.IsValid(&why)) {
    throw std::invalid_argument("HoughOptions: " + why);
  }
  PlaneSearch search;
  Poller poller(options.stop);
  const auto stopped = [&] {
    search.status = PlaneSearchStatus::kStopped;
    search.planes.clear();
    return search;
  };
  double max_norm_m = 0.0;
  std::vector<WeightedPoint> points = CollectVoters(tree, options, &poller, &max_norm_m);
  if (poller.stopped()) return stopped();
  search.voters = points.size();
  if (points.empty()) return search;
  Accumulator acc(options, max_norm_m);
  search.accumulator_cells = acc.needed_cells();
  if (options.max_accumulator_cells > 0 && search.accumulator_cells > options.max_accumulator_cells) {
    search.status = PlaneSearchStatus::kTooLarge;
    return search;
  }
  acc.Allocate();
  const double res = tree.getResolution();
  std::vector<WeightedPoint> voters =
      options.vote_merge_voxels > 1 ? MergedVoters(points, options.vote_merge_voxels * res, &poller)
                                    : points;
  if (poller.stopped()) return stopped();
  // Coarse to fine on fine maps (cubes under vote_cube_min_m): every normal voted by cubes of
  // twice the edge (a quarter of the votes; a centroid of centroids weighted by their sums is
  // the centroid of the voxels), then the strong normals voted again by the voters themselves.
  // The coarse cubes' peaks alone pick worse planes on a warped floor (TUM at 2 cm: 5 cm off).
  // Not larger cubes: a cube votes all its voxels' weight into one bin of every normal, and on
  // a thick surface (a stereo wall at 1 cm: ~3 000 voxels in a cube of 16) single cubes make
  // peaks at every normal.
  const int merge = options.vote_merge_voxels;
  if (options.vote_cube_min_m > merge * res + 1e-9) {
    Vote(MergedVoters(voters, 2 * merge * res, &poller), {}, &acc, &poller);
    if (poller.stopped()) return stopped();
    Vote(voters, ClearStrongRows(&acc), &acc, &poller);
  } else {
    Vote(voters, {}, &acc, &poller);
  }
  if (poller.stopped()) return stopped();
  // A cell with fewer votes than a quarter of the least support a plane may have (its voxels
  // at the least occupancy that votes) cannot become one: its neighbours are not looked at.
  const auto min_votes = static_cast<float>(0.25 * static_cast<double>(options.min_support_voxels) *
                                            std::max(options.min_probability, 0.01));
  const std::vector<Peak> peaks = FindPeaks(acc, min_votes, &poller);
  if (poller.stopped()) return stopped();
  const double band = options.support_distance_m > 0.0 ? options.support_distance_m
                                                        : 1.5 * tree.getResolution();
  // Candidates are refined, judged and claim their support on the (few) voters; only the
  // planes found are refined on the voxels.
  const std::vector<Plane> found = ExtractPlanes(peaks, &voters, options, band, &poller);
  if (poller.stopped()) return stopped();
  search.planes = RefineOnVoxels(found, &points, options, band, &poller);
  if (poller.stopped()) return stopped();
  return search;
}

std::vector<Plane> DetectPlanes(const octomap::OcTree& tree, const HoughOptions& options) {
  return SearchPlanes(tree, options).planes;
}

}  // namespace fusion
