// accuracy_real: maps of the real recordings in ../shared/data made by core (one row per sensor
// description) and by OctoMap's insertPointCloud at the same resolution, measured against the
// points themselves (BENCHMARKS.md, "Accuracy on real data"). A benchmark program, not a test:
//
//   build/tests/accuracy_real [--data DIR] [--resolution M] [--stride N] [--only tum,scan,pcd]
//
// TUM fr2/pioneer_slam2 (10 Kinect frames with ground-truth poses): every model maps the same
// frames; the floor (world z ~ 0) is fitted robustly from the points, and the map is judged by
// how many of its occupied voxels hold / lie within one voxel of a measured point, and by the
// floor's thickness and offset over "clean" floor columns (map columns whose points all lie
// within 4 cm of the fitted floor). FindPlanes' search (the service's defaults) on each map, ours
// and OctoMap's, reports how the floor comes back. The PCD stereo frame (PCL's table scene) is
// judged the same way against its table top.
#include <octomap/OcTree.h>

#include <Eigen/Geometry>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <filesystem>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <unordered_map>
#include <unordered_set>
#include <vector>

#include "../service/tum_map_bench_recording.h"
#include "fusion/clients/importers.h"
#include "fusion/core/beam_grid.h"
#include "fusion/core/calibration.h"
#include "fusion/core/planes.h"
#include "fusion/core/world_map.h"
#include "fusion/service/config.h"

namespace {

using Clock = std::chrono::steady_clock;
using fusion::tum_map_bench::Frame;
constexpr double kPi = 3.14159265358979323846;

// The beam prior's reference length of core's maps (--beam-prior).
double g_beam_prior_m = fusion::WorldMapOptions::kDefaultBeamPriorLengthM;

struct Options {
  std::string data_dir;
  double resolution_m = 0.02;
  double scan_resolution_m = 0.05;
  double pcd_resolution_m = 0.01;
  int stride = 4;
  int scan_cols = 0, scan_rows = 0;  // the scan's beam grid; 0: the laser_3d preset's
  std::string only;  // empty: every part; else a comma-separated list of tum, scan, pcd
  [[nodiscard]] bool Runs(const std::string& part) const {
    return only.empty() || ("," + only + ",").find("," + part + ",") != std::string::npos;
  }
};

constexpr const char* kUsage =
    "usage: accuracy_real [--data DIR] [--resolution M] [--stride N] [--scan-resolution M]\n"
    "                     [--pcd-resolution M] [--beam-prior M] [--scan-grid COLSxROWS]\n"
    "                     [--only tum,scan,pcd]\n"
    "  --data        the real recordings (default ../shared/data beside the project)\n"
    "  --resolution  map voxel edge in metres (default 0.02)\n"
    "  --stride      TUM: every N-th pixel in both directions (default 4; 1 = every pixel)\n"
    "  --scan-resolution  the laser scan's map voxel edge in metres (default 0.05)\n"
    "  --pcd-resolution   the PCD stereo frame's map voxel edge in metres (default 0.01)\n"
    "  --beam-prior  the maps' beam prior length in metres, for sensors without their own\n"
    "                (default 1; the laser_3d preset brings 5)\n"
    "  --scan-grid   the laser scan's beams across x up over the preset's field of view\n"
    "                (default the laser_3d preset's 368x2048)\n"
    "  --only        the parts to run, comma-separated: tum, scan, pcd (default all)\n"
    "environment: ACCURACY_REAL_PLANES=1 lists every plane FindPlanes finds\n";

bool ParseArgs(int argc, char** argv, Options* o) {
  o->data_dir = (std::filesystem::path(FUSION_SOURCE_DIR) / ".." / "shared" / "data")
                    .lexically_normal()
                    .string();
  for (int i = 1; i < argc; ++i) {
    const std::string flag = argv[i];
    if (flag == "--help" || flag == "-h") {
      std::fputs(kUsage, stdout);
      std::exit(0);
    }
    if (i + 1 >= argc) {
      std::fprintf(stderr, "%s needs a value\n%s", flag.c_str(), kUsage);
      return false;
    }
    const std::string value = argv[++i];
    if (flag == "--data") {
      o->data_dir = value;
    } else if (flag == "--resolution") {
      o->resolution_m = std::atof(value.c_str());
    } else if (flag == "--beam-prior") {
      g_beam_prior_m = std::atof(value.c_str());
    } else if (flag == "--scan-grid") {
      if (std::sscanf(value.c_str(), "%dx%d", &o->scan_cols, &o->scan_rows) != 2 ||
          o->scan_cols < 1 || o->scan_rows < 1 || o->scan_cols > 4096 || o->scan_rows > 4096) {
        std::fprintf(stderr, "--scan-grid wants COLSxROWS, each 1..4096 (got %s)\n",
                     value.c_str());
        return false;
      }
    } else if (flag == "--scan-resolution") {
      o->scan_resolution_m = std::atof(value.c_str());
    } else if (flag == "--pcd-resolution") {
      o->pcd_resolution_m = std::atof(value.c_str());
    } else if (flag == "--only") {
      o->only = value;
    } else if (flag == "--stride") {
      o->stride = std::atoi(value.c_str());
    } else {
      std::fprintf(stderr, "unknown flag %s\n%s", flag.c_str(), kUsage);
      return false;
    }
  }
  if (!(o->resolution_m >= 0.005 && o->resolution_m <= 1.0) ||
      !(o->scan_resolution_m >= 0.01 && o->scan_resolution_m <= 1.0) ||
      !(o->pcd_resolution_m >= 0.002 && o->pcd_resolution_m <= 0.2) || o->stride < 1 ||
      o->stride > 16) {
    std::fprintf(stderr, "--resolution must lie in [0.005, 1] m, --scan-resolution in [0.01, 1] m, "
                 "--pcd-resolution in [0.002, 0.2] m and --stride in 1..16\n");
    return false;
  }
  for (std::size_t begin = 0; !o->only.empty() && begin <= o->only.size();) {
    const std::size_t end = std::min(o->only.find(',', begin), o->only.size());
    const std::string part = o->only.substr(begin, end - begin);
    if (part != "tum" && part != "scan" && part != "pcd") {
      std::fprintf(stderr, "--only: unknown part '%s' (tum, scan, pcd)\n", part.c_str());
      return false;
    }
    begin = end + 1;
  }
  return true;
}

double SecondsSince(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

// This process's CPU time (s): on a shared machine, what a single-threaded step would take alone.
double CpuSeconds() { return static_cast<double>(std::clock()) / CLOCKS_PER_SEC; }

// ---- the maps ----------------------------------------------------------------------------------

// A map as made, and how long it took.
struct Built {
  std::unique_ptr<octomap::OcTree> tree;
  double time_s = 0.0;
};

// Calls f(key, log_odds) for every voxel of the finest depth (coarse leaves expanded).
template <typename F>
void ForEachVoxel(const octomap::OcTree& tree, F&& f) {
  for (auto it = tree.begin_leafs(), end = tree.end_leafs(); it != end; ++it) {
    const int side = 1 << (tree.getTreeDepth() - it.getDepth());
    const octomap::OcTreeKey k0 = it.getIndexKey();
    const float l = it->getLogOdds();
    for (int x = 0; x < side; ++x)
      for (int y = 0; y < side; ++y)
        for (int z = 0; z < side; ++z) f(octomap::OcTreeKey(k0[0] + x, k0[1] + y, k0[2] + z), l);
  }
}

float LogOdds(double p) { return static_cast<float>(std::log(p / (1.0 - p))); }

// A map's occupied voxels at the finest depth.
std::vector<octomap::OcTreeKey> OccupiedVoxels(const octomap::OcTree& tree,
                                               double occupied_threshold) {
  std::vector<octomap::OcTreeKey> out;
  const float l_occ = LogOdds(occupied_threshold);
  ForEachVoxel(tree, [&](const octomap::OcTreeKey& k, float l) {
    if (l >= l_occ) out.push_back(k);
  });
  return out;
}

std::optional<Built> MapWithCore(const fusion::SensorSpec& spec, double resolution_m,
                                 const std::vector<Frame>& frames) {
  fusion::WorldMapOptions options;
  options.beam_prior_length_m = g_beam_prior_m;
  options.resolution_m = resolution_m;
  options.render.resolution_m = resolution_m;
  fusion::WorldMap map(options);
  if (map.AddSensor(spec.name, spec) != fusion::MapStatus::kOk) return std::nullopt;
  const auto t0 = Clock::now();
  for (const Frame& f : frames) {
    if (map.Integrate(spec.name, f.T_world_sensor, f.xyz.data(), f.xyz.size() / 3) !=
            fusion::MapStatus::kOk ||
        map.Render(spec.name) != fusion::MapStatus::kOk) {
      return std::nullopt;
    }
  }
  Built b;
  b.time_s = SecondsSince(t0);
  b.tree = std::make_unique<octomap::OcTree>(map.tree());
  return b;
}

// OctoMap's insertPointCloud of the same points at the same resolution (max_range_m < 0: no
// limit), OctoMap's default sensor model.
Built MapWithOctoMap(double resolution_m, double max_range_m, const std::vector<Frame>& frames) {
  Built b;
  b.tree = std::make_unique<octomap::OcTree>(resolution_m);
  const auto t0 = Clock::now();
  for (const Frame& f : frames) {
    octomap::Pointcloud cloud;
    for (std::size_t i = 0; i + 2 < f.xyz.size(); i += 3) {
      const Eigen::Vector3d p(f.xyz[i], f.xyz[i + 1], f.xyz[i + 2]);
      if (!p.allFinite()) continue;
      const Eigen::Vector3d w = f.T_world_sensor * p;
      cloud.push_back(static_cast<float>(w.x()), static_cast<float>(w.y()),
                      static_cast<float>(w.z()));
    }
    const Eigen::Vector3d o = f.T_world_sensor.translation();
    b.tree->insertPointCloud(cloud, octomap::point3d(o.x(), o.y(), o.z()), max_range_m);
  }
  b.time_s = SecondsSince(t0);
  return b;
}

// ---- the points and what they say ----------------------------------------------------------------

struct KeyHash {
  std::size_t operator()(const octomap::OcTreeKey& k) const {
    return (static_cast<std::size_t>(k[0]) << 32) ^ (static_cast<std::size_t>(k[1]) << 16) ^ k[2];
  }
};
using KeySet = std::unordered_set<octomap::OcTreeKey, KeyHash>;

// A known plane of a data set (the TUM floor, the PCD table) fitted robustly to the points, and
// the map columns that cross it: columns run along the key axis nearest the plane's normal, and
// a column is "clean" when every point in it lies within 4 cm of the plane.
struct KnownPlane {
  fusion::PlaneCoefficients plane = fusion::PlaneCoefficients(0, 0, 1, 0);  // n . p + c = 0
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();  // of the points on it
  int axis = 2;
  std::map<std::pair<int, int>, bool> columns;
  [[nodiscard]] Eigen::Vector3d normal() const { return plane.head<3>(); }
  [[nodiscard]] double Distance(const Eigen::Vector3d& p) const {
    return plane.head<3>().dot(p) + plane[3];
  }
  [[nodiscard]] std::pair<int, int> Column(const octomap::OcTreeKey& k) const {
    return {int(k[(axis + 1) % 3]), int(k[(axis + 2) % 3])};
  }
};

struct Evidence {
  octomap::OcTree grid;  // only for its key <-> coordinate conversions
  KeySet point_voxels;   // voxels holding a measured point (within the sensor's range)
  KnownPlane known;
  explicit Evidence(double resolution_m) : grid(resolution_m) {}
};

// The plane through most of `candidates` (RANSAC + refinement, inliers within inlier_m), its
// normal towards `towards`; its columns from every point of `world`.
std::optional<KnownPlane> FitKnownPlane(const std::vector<Eigen::Vector3d>& candidates,
                                        const std::vector<Eigen::Vector3d>& world,
                                        const Eigen::Vector3d& towards, double inlier_m,
                                        const octomap::OcTree& grid, double* rms_m) {
  fusion::PlaneFitOptions fit;
  fit.inlier_distance_m = inlier_m;
  const fusion::PlaneFit found = fusion::FitDominantPlane(candidates, fit);
  if (!found.ok()) {
    std::fprintf(stderr, "plane fit: %s\n", found.error.c_str());
    return std::nullopt;
  }
  KnownPlane k;
  k.plane = found.plane;
  if (k.normal().dot(towards) < 0) k.plane = -k.plane;
  *rms_m = found.rms_m;
  std::size_t on = 0;
  for (const Eigen::Vector3d& p : candidates) {
    if (std::abs(k.Distance(p)) > inlier_m) continue;
    k.centroid += p;
    ++on;
  }
  k.centroid /= static_cast<double>(std::max<std::size_t>(1, on));
  k.normal().cwiseAbs().maxCoeff(&k.axis);
  for (const Eigen::Vector3d& w : world) {
    const bool clean = std::abs(k.Distance(w)) <= 0.04;
    const auto [it, inserted] = k.columns.emplace(k.Column(grid.coordToKey(w.x(), w.y(), w.z())), clean);
    if (!inserted) it->second = it->second && clean;
  }
  return k;
}

// The frames' points in the world within max_range_m of their sensor.
std::vector<Eigen::Vector3d> WorldPoints(const std::vector<Frame>& frames, double max_range_m) {
  std::vector<Eigen::Vector3d> world;
  for (const Frame& f : frames) {
    for (std::size_t i = 0; i + 2 < f.xyz.size(); i += 3) {
      const Eigen::Vector3d p(f.xyz[i], f.xyz[i + 1], f.xyz[i + 2]);
      if (p.allFinite() && p.norm() <= max_range_m) world.push_back(f.T_world_sensor * p);
    }
  }
  return world;
}

std::optional<Evidence> GatherEvidence(const std::vector<Frame>& frames, double resolution_m,
                                       double max_range_m) {
  Evidence e(resolution_m);
  const std::vector<Eigen::Vector3d> world = WorldPoints(frames, max_range_m);
  std::vector<Eigen::Vector3d> near_floor;
  for (const Eigen::Vector3d& w : world) {
    if (std::abs(w.z()) < 0.15) near_floor.push_back(w);
  }
  double rms_m = 0.0;
  const auto floor = FitKnownPlane(near_floor, world, Eigen::Vector3d::UnitZ(), 0.02, e.grid, &rms_m);
  if (!floor) return std::nullopt;
  e.known = *floor;
  for (const Eigen::Vector3d& w : world) e.point_voxels.insert(e.grid.coordToKey(w.x(), w.y(), w.z()));
  const fusion::PlaneCoefficients& f = e.known.plane;
  const double tilt_deg = std::acos(std::min(1.0, f[2])) * 180.0 / kPi;
  std::printf("points: %zu within %.1f m, %zu voxels hold one; floor fitted from %zu points "
              "near z = 0: %.4f x + %.4f y + %.4f z + %.4f = 0 (tilt %.2f deg, rms %.1f mm)\n",
              world.size(), max_range_m, e.point_voxels.size(), near_floor.size(), f[0], f[1], f[2],
              f[3], tilt_deg, 1000.0 * rms_m);
  return e;
}

struct Scores {
  std::size_t occupied = 0;
  double holding = 0.0, within_one = 0.0;  // shares of the occupied voxels
  // The known plane over its clean columns: thickness along its normal, mean offset, coverage.
  double plane_thickness_mm = 0.0, plane_offset_mm = 0.0, plane_coverage = 0.0;
};

bool NearAPoint(const KeySet& points, const octomap::OcTreeKey& k) {
  for (int dx = -1; dx <= 1; ++dx)
    for (int dy = -1; dy <= 1; ++dy)
      for (int dz = -1; dz <= 1; ++dz) {
        if (points.count(octomap::OcTreeKey(k[0] + dx, k[1] + dy, k[2] + dz))) return true;
      }
  return false;
}

// Per clean column of the known plane: the occupied voxels within 0.3 m of the plane, times the
// voxel edge and the cosine between the column and the normal (thickness along the normal).
Scores Score(const std::vector<octomap::OcTreeKey>& occupied, const Evidence& e) {
  Scores s;
  s.occupied = occupied.size();
  std::size_t holding = 0, near = 0;
  struct Column {
    int voxels = 0;
    double offset_sum_m = 0.0;
  };
  std::map<std::pair<int, int>, Column> columns;
  for (const octomap::OcTreeKey& k : occupied) {
    holding += e.point_voxels.count(k);
    near += NearAPoint(e.point_voxels, k) ? 1 : 0;
    const auto column = e.known.Column(k);
    const auto it = e.known.columns.find(column);
    if (it == e.known.columns.end() || !it->second) continue;
    const octomap::point3d c = e.grid.keyToCoord(k);
    const double d = e.known.Distance(Eigen::Vector3d(c.x(), c.y(), c.z()));
    if (std::abs(d) > 0.3) continue;
    Column& col = columns[column];
    ++col.voxels;
    col.offset_sum_m += d;
  }
  const double n = std::max<double>(1, s.occupied);
  s.holding = holding / n;
  s.within_one = near / n;
  std::size_t clean = 0;
  for (const auto& [key, is_clean] : e.known.columns) clean += is_clean ? 1 : 0;
  double thickness = 0.0, offset = 0.0;
  const double along = std::abs(e.known.normal()[e.known.axis]);
  for (const auto& [key, col] : columns) {
    thickness += col.voxels * e.grid.getResolution() * along;
    offset += col.offset_sum_m / col.voxels;
  }
  const double m = std::max<double>(1, columns.size());
  s.plane_thickness_mm = 1000.0 * thickness / m;
  s.plane_offset_mm = 1000.0 * offset / m;
  s.plane_coverage = static_cast<double>(columns.size()) / std::max<std::size_t>(1, clean);
  return s;
}

// FindPlanes' search with the service's defaults (angle bins 2 degrees, distance bins of the map
// resolution; HoughOptionsFromProto of an empty request) on a map, in an optional region: how the
// known plane comes back. A found plane is the known one when its normal lies within 10 degrees
// of the known normal and the centre of its support's box within 0.1 m (the search's
// suppression distance) of the known plane: a plane that only crosses it elsewhere, tilted,
// with its support on something else, is not. Its angle and height are measured against the
// known plane where the known plane's points are (their centroid).
struct KnownPlanes {
  std::size_t planes = 0, copies = 0;  // planes found; of them the known plane
  std::size_t first_rank = 0;          // 1-based rank of the first copy (0: none)
  double angle_deg = 0.0, height_mm = 0.0, time_s = 0.0, cpu_s = 0.0;
  std::size_t support_voxels = 0;
};

KnownPlanes FindKnownPlanes(const octomap::OcTree& tree, const KnownPlane& known,
                            const std::optional<Eigen::AlignedBox3d>& region = std::nullopt) {
  fusion::HoughOptions options;
  options.d_bin_m = tree.getResolution();  // the service's default distance step
  options.region = region;
  KnownPlanes f;
  const auto t0 = Clock::now();
  const double cpu0 = CpuSeconds();
  const fusion::PlaneSearch search = fusion::SearchPlanes(tree, options);
  f.time_s = SecondsSince(t0);
  f.cpu_s = CpuSeconds() - cpu0;
  f.planes = search.planes.size();
  const Eigen::Vector3d n_known = known.normal();
  for (std::size_t i = 0; i < search.planes.size(); ++i) {
    const fusion::Plane& p = search.planes[i];
    const double angle = std::acos(std::min(1.0, std::abs(p.normal.dot(n_known)))) * 180.0 / kPi;
    if (std::getenv("ACCURACY_REAL_PLANES")) {
      std::printf("    plane %zu: n (%.3f %.3f %.3f) d %.3f m, %zu voxels, %.2f deg from the known, "
                  "support box centre %+.3f m from it\n", i + 1, p.normal.x(), p.normal.y(),
                  p.normal.z(), p.distance_m, p.support_voxels, angle,
                  known.Distance(p.extent.center()));
    }
    if (angle > 10.0 || std::abs(known.Distance(p.extent.center())) > 0.1) continue;
    if (f.copies++ > 0) continue;
    // Height of this plane above the known one along the known normal through the centroid.
    const double along = p.normal.dot(n_known);
    f.angle_deg = angle;
    f.height_mm = 1000.0 * (p.distance_m - p.normal.dot(known.centroid)) / along;
    f.first_rank = i + 1;
    f.support_voxels = p.support_voxels;
  }
  return f;
}

void PrintKnownPlanes(const std::string& name, const std::string& what, const KnownPlanes& f) {
  std::printf("  %s: FindPlanes %.2f s (%.2f s CPU), %zu planes, %zu of them the %s", name.c_str(),
              f.time_s, f.cpu_s, f.planes, f.copies, what.c_str());
  if (f.copies == 0) {
    std::printf("\n");
    return;
  }
  std::printf("; the first (rank %zu, %zu voxels) %.2f deg and %+.1f mm from the fitted %s\n",
              f.first_rank, f.support_voxels, f.angle_deg, f.height_mm, what.c_str());
}

void PrintRow(const std::string& name, double time_s, const Scores& s) {
  std::printf("| %s | %zu | %.1f %% | %.1f %% | %.1f | %+.1f | %.1f %% | %.2f |\n", name.c_str(),
              s.occupied, 100.0 * s.holding, 100.0 * s.within_one, s.plane_thickness_mm,
              s.plane_offset_mm, 100.0 * s.plane_coverage, time_s);
}

// ---- TUM -------------------------------------------------------------------------------------

// The Kinect as typed by hand before calibration (e2e_tum_test.cc): sigma(r) = 0.0012 +
// 0.0019 (r - 0.4)^2 m, no bias, eps 0.02, on a grid of the pixels (pinhole) or of angles.
fusion::SensorSpec HandKinect(int stride, bool pinhole) {
  fusion::SensorSpec s = *fusion::SensorPreset("kinect_v1");
  s.q_mu = {0.0, 1.0, 0.0};
  s.q_sigma = {0.0019, -2.0 * 0.0019 * 0.4, 0.0012 + 0.0019 * 0.16};
  s.epsilon = 0.02;
  fusion::PinholeIntrinsics k = *s.pinhole;
  k.stride = stride;
  fusion::SetPinhole(k, &s);
  if (!pinhole) {
    // The symmetric FOV that covers every pixel (principal point off centre), as before.
    s.pinhole.reset();
    s.fov_h_rad = 2.0 * std::atan(325.1 / 520.9) + 0.5 * kPi / 180.0;
    s.fov_v_rad = 2.0 * std::atan(249.7 / 521.0) + 0.5 * kPi / 180.0;
    s.azimuth_centre_rad = s.elevation_centre_rad = 0.0;
  }
  return s;
}

int RunTum(const Options& o) {
  const std::string dir = o.data_dir + "/tum_fr2_pioneer_slam2";
  if (!std::filesystem::exists(dir)) {
    std::printf("TUM: %s is missing: skipped\n", dir.c_str());
    return 0;
  }
  fusion::clients::TumOptions tum;
  tum.directory = dir;
  tum.stride = static_cast<std::uint32_t>(o.stride);
  std::vector<Frame> frames;
  const fusion::Status imported = fusion::clients::ImportTum(tum, [&](fusion::v1::RecordedCloud&& c) {
    frames.push_back(fusion::tum_map_bench::FrameOf(c));
    return fusion::Status::Ok();
  });
  if (!imported.ok()) {
    std::fprintf(stderr, "TUM import: %s\n", imported.message().c_str());
    return 1;
  }
  const fusion::SensorSpec preset = HandKinect(o.stride, true);
  const auto evidence = GatherEvidence(frames, o.resolution_m, preset.r_max_m);
  if (!evidence) return 1;
  const double occupied_threshold =
      fusion::service::DefaultConfig().map().occupied_threshold();
  std::printf("\n## TUM fr2/pioneer_slam2: %zu frames, every %d-th pixel, %.3f m voxels\n\n",
              frames.size(), o.stride, o.resolution_m);
  std::printf("| map | occupied voxels | holding a point | within one voxel of a point | "
              "clean-floor thickness (mm) | floor offset (mm) | clean floor columns covered | "
              "time (s) |\n|---|---|---|---|---|---|---|---|\n");
  fusion::SensorSpec fitted = *fusion::SensorPreset("kinect_v1");
  fusion::PinholeIntrinsics k = *fitted.pinhole;
  k.stride = o.stride;
  fusion::SetPinhole(k, &fitted);
  const std::pair<std::string, fusion::SensorSpec> rows[] = {
      {"ours, hand-typed model, angular grid", HandKinect(o.stride, false)},
      {"ours, hand-typed model, pinhole grid", HandKinect(o.stride, true)},
      {"ours, kinect_v1 preset (fitted model, pinhole grid)", fitted},
  };
  std::vector<std::pair<std::string, KnownPlanes>> planes;
  for (const auto& [name, spec] : rows) {
    const auto map = MapWithCore(spec, o.resolution_m, frames);
    if (!map) {
      std::fprintf(stderr, "%s: the map refused the sensor or a frame\n", name.c_str());
      return 1;
    }
    PrintRow(name, map->time_s, Score(OccupiedVoxels(*map->tree, occupied_threshold), *evidence));
    planes.emplace_back(name, FindKnownPlanes(*map->tree, evidence->known));
    std::fflush(stdout);
  }
  const Built octomap = MapWithOctoMap(o.resolution_m, preset.r_max_m, frames);
  PrintRow("OctoMap insertPointCloud", octomap.time_s,
           Score(OccupiedVoxels(*octomap.tree, octomap.tree->getOccupancyThres()), *evidence));
  planes.emplace_back("OctoMap insertPointCloud", FindKnownPlanes(*octomap.tree, evidence->known));
  std::printf("\nplanes (FindPlanes' defaults: 2-degree bins, distance bins of the voxel edge):\n");
  for (const auto& [name, f] : planes) PrintKnownPlanes(name, "floor", f);
  return 0;
}

// ---- agreement with OctoMap by class and range ------------------------------------------------

struct Band {
  double lo_m = 0.0, hi_m = 0.0;
  std::size_t octo_occupied = 0, occupied_near = 0;           // ours occupied within one voxel
  std::size_t octo_free = 0, free_free = 0, free_unknown = 0;  // ours free / unknown there
};

struct Classes {
  float occupied_log_odds = 0.0f, free_log_odds = 0.0f;
  [[nodiscard]] int Of(const octomap::OcTree& tree, const octomap::OcTreeKey& k) const {
    const octomap::OcTreeNode* n = tree.search(k);
    if (n == nullptr) return 0;  // unknown
    if (n->getLogOdds() >= occupied_log_odds) return 1;
    return n->getLogOdds() <= free_log_odds ? -1 : 0;
  }
};

// OctoMap's voxels by class and by the range of their centre from `origin`: how ours classifies
// them (occupied: at the voxel or a neighbour).
std::vector<Band> CompareByBand(const octomap::OcTree& ours, const Classes& classes,
                                const octomap::OcTree& octo, const Eigen::Vector3d& origin,
                                const std::vector<double>& edges_m) {
  std::vector<Band> bands;
  for (std::size_t i = 0; i + 1 < edges_m.size(); ++i) bands.push_back({edges_m[i], edges_m[i + 1]});
  const float octo_occupied = octo.getOccupancyThresLog();
  ForEachVoxel(octo, [&](const octomap::OcTreeKey& k, float l) {
    const octomap::point3d c = octo.keyToCoord(k);
    const double r = (Eigen::Vector3d(c.x(), c.y(), c.z()) - origin).norm();
    Band* band = nullptr;
    for (Band& b : bands) {
      if (r >= b.lo_m && r < b.hi_m) band = &b;
    }
    if (band == nullptr) return;
    if (l >= octo_occupied) {
      ++band->octo_occupied;
      bool near = false;
      for (int dx = -1; dx <= 1 && !near; ++dx)
        for (int dy = -1; dy <= 1 && !near; ++dy)
          for (int dz = -1; dz <= 1 && !near; ++dz) {
            near = classes.Of(ours, octomap::OcTreeKey(k[0] + dx, k[1] + dy, k[2] + dz)) == 1;
          }
      band->occupied_near += near ? 1 : 0;
    } else {
      ++band->octo_free;
      const int mine = classes.Of(ours, k);
      band->free_free += mine == -1 ? 1 : 0;
      band->free_unknown += mine == 0 ? 1 : 0;
    }
  });
  return bands;
}

void PrintBands(const std::vector<Band>& bands) {
  std::printf("\n| range band (m) | OctoMap occupied | of them occupied in ours (within one voxel) "
              "| OctoMap free | of them free in ours | unknown in ours |\n"
              "|---|---|---|---|---|---|\n");
  Band all;
  for (const Band& b : bands) {
    const auto share = [](std::size_t a, std::size_t n) { return n ? 100.0 * a / n : 0.0; };
    std::printf("| %.0f-%.0f | %zu | %.1f %% | %zu | %.1f %% | %.1f %% |\n", b.lo_m, b.hi_m,
                b.octo_occupied, share(b.occupied_near, b.octo_occupied), b.octo_free,
                share(b.free_free, b.octo_free), share(b.free_unknown, b.octo_free));
    all.octo_occupied += b.octo_occupied;
    all.occupied_near += b.occupied_near;
    all.octo_free += b.octo_free;
    all.free_free += b.free_free;
    all.free_unknown += b.free_unknown;
  }
  std::printf("| all | %zu | %.1f %% | %zu | %.1f %% | %.1f %% |\n", all.octo_occupied,
              100.0 * all.occupied_near / std::max<std::size_t>(1, all.octo_occupied),
              all.octo_free, 100.0 * all.free_free / std::max<std::size_t>(1, all.octo_free),
              100.0 * all.free_unknown / std::max<std::size_t>(1, all.octo_free));
}

// ---- the laser scan's beam grid ------------------------------------------------------------

// OctoMap's sample scan (body frame, -91..91 x -7..32 degrees) held by a grid symmetric about
// the optical axis at 0.1-degree beams (what it needed before asymmetric grids) and by the
// laser_3d preset: beams and memory after integrating the scan, at the service's beam cell.
int RunScanGrid(const Options& o) {
  const std::string path = o.data_dir + "/octomap_laser_scan/scan.dat.bz2";
  if (!std::filesystem::exists(path)) {
    std::printf("laser scan: %s is missing: skipped\n", path.c_str());
    return 0;
  }
  fusion::v1::RecordedPose origin;
  origin.set_qw(1.0);
  std::vector<fusion::v1::RecordedCloud> clouds;
  if (const fusion::Status s = fusion::clients::ReadXyzScan(path, origin, &clouds); !s.ok()) {
    std::fprintf(stderr, "laser scan: %s\n", s.message().c_str());
    return 1;
  }
  fusion::clients::ToOpticalFrame(fusion::clients::PointFrame::kBody, &clouds.at(0));
  const Frame scan = fusion::tum_map_bench::FrameOf(clouds[0]);
  fusion::BeamGridOptions options = fusion::WorldMapOptions().beam_grid;
  options.cell_size_m = fusion::service::DefaultConfig().map().beam_cell_size_m();
  fusion::SensorSpec symmetric = *fusion::SensorPreset("laser_3d");
  fusion::SetAngularLimits(-92.0 * kPi / 180, 92.0 * kPi / 180, -32.25 * kPi / 180,
                           32.25 * kPi / 180, &symmetric);
  symmetric.cols = 1840;
  symmetric.rows = 645;
  std::printf("\n## OctoMap's laser scan: %zu points, beam cells of %.3f m\n\n| grid | beams | "
              "readings in the grid | beam grid memory (MB) |\n|---|---|---|---|\n",
              scan.xyz.size() / 3, options.cell_size_m);
  const auto coarser = [](int cols, int rows) {
    fusion::SensorSpec s = *fusion::SensorPreset("laser_3d");
    s.cols = cols;
    s.rows = rows;
    return s;
  };
  std::vector<std::pair<std::string, fusion::SensorSpec>> grids = {
      {"symmetric, 184 x 64.5 degrees at 0.1 degree", symmetric},
      {"asymmetric 184 x 41 degrees at 0.5 degree", coarser(368, 82)},
      {"asymmetric 184 x 41 degrees at 0.25 degree", coarser(736, 164)},
      {"laser_3d: asymmetric 184 x 41 degrees, 0.5 degree across, 0.02 degree up",
       *fusion::SensorPreset("laser_3d")},
  };
  if (o.scan_cols > 0) {
    grids.emplace_back("--scan-grid " + std::to_string(o.scan_cols) + "x" +
                           std::to_string(o.scan_rows),
                       coarser(o.scan_cols, o.scan_rows));
  }
  for (const auto& [name, spec] : grids) {
    fusion::BeamGrid grid(spec, options);
    const fusion::IntegrationStats stats = grid.Integrate(scan.xyz.data(), scan.xyz.size() / 3);
    std::printf("| %s | %zu | %zu | %.1f |\n", name.c_str(), grid.beam_count(), stats.updated,
                static_cast<double>(grid.MemoryBytes()) / 1e6);
  }
  // The map: ours with the laser_3d preset against OctoMap's, every return (no max range).
  const std::vector<Frame> frames = {scan};
  const fusion::SensorSpec laser =
      o.scan_cols > 0 ? coarser(o.scan_cols, o.scan_rows) : *fusion::SensorPreset("laser_3d");
  const auto ours = MapWithCore(laser, o.scan_resolution_m, frames);
  if (!ours) {
    std::fprintf(stderr, "laser scan: the map refused the sensor or the scan\n");
    return 1;
  }
  const Built octomap = MapWithOctoMap(o.scan_resolution_m, -1.0, frames);
  const fusion::v1::MapConfig config = fusion::service::DefaultConfig().map();  // a copy: not a temporary's member
  const Classes classes{LogOdds(config.occupied_threshold()), LogOdds(config.free_threshold())};
  std::printf("\nmaps at %.3f m: ours (laser_3d, %d x %d beams) %zu occupied voxels in %.2f s, "
              "OctoMap %zu in %.2f s\n",
              o.scan_resolution_m, laser.cols, laser.rows, OccupiedVoxels(*ours->tree, config.occupied_threshold()).size(),
              ours->time_s, OccupiedVoxels(*octomap.tree, 0.5).size(), octomap.time_s);
  PrintBands(CompareByBand(*ours->tree, classes, *octomap.tree, scan.T_world_sensor.translation(),
                           {0.0, 2.0, 5.0, 10.0, 20.0, 30.0}));
  return 0;
}

// ---- the PCD stereo frame ----------------------------------------------------------------------

// PCL's table_scene_mug_stereo_textured.pcd (one 640 x 480 stereo frame, camera frame, the
// VIEWPOINT ignored) with the stereo camera of e2e_pcd_test.cc: 37 x 30 degrees in 160 x 120
// beams, sigma(r) = 3 mm + 4 mm/m^2 r^2, r in [0.3, 3] m. The table top (the plane through most
// points) is fitted to the points; each map is judged as the TUM maps are, against the table.
fusion::SensorSpec PcdStereo() {
  fusion::SensorSpec s;
  s.name = "stereo";
  s.model = fusion::ForwardModelKind::kPaper3d;
  s.r_min_m = 0.3;
  s.r_max_m = 3.0;
  s.fov_h_rad = 37.0 * kPi / 180.0;
  s.fov_v_rad = 30.0 * kPi / 180.0;
  s.cols = 160;
  s.rows = 120;
  s.epsilon = 0.02;
  s.q_mu = {0.0, 1.0, 0.0};
  s.q_sigma = {0.004, 0.0, 0.003};
  return s;
}

int RunPcd(const Options& o) {
  const std::string path = o.data_dir + "/pcl_stereo/table_scene_mug_stereo_textured.pcd";
  if (!std::filesystem::exists(path)) {
    std::printf("PCD: %s is missing: skipped\n", path.c_str());
    return 0;
  }
  fusion::v1::RecordedCloud cloud;
  if (const fusion::Status s = fusion::clients::ReadPcd(path, &cloud, false); !s.ok()) {
    std::fprintf(stderr, "PCD: %s\n", s.message().c_str());
    return 1;
  }
  const std::vector<Frame> frames = {fusion::tum_map_bench::FrameOf(cloud)};
  const fusion::SensorSpec spec = PcdStereo();
  Evidence e(o.pcd_resolution_m);
  const std::vector<Eigen::Vector3d> world = WorldPoints(frames, spec.r_max_m);
  double rms_m = 0.0;
  // Normal towards the camera's up (-y in its optical frame): heights above the table positive.
  const auto table = FitKnownPlane(world, world, -Eigen::Vector3d::UnitY(), 0.01, e.grid, &rms_m);
  if (!table) return 1;
  e.known = *table;
  for (const Eigen::Vector3d& w : world) e.point_voxels.insert(e.grid.coordToKey(w.x(), w.y(), w.z()));
  std::size_t on_table = 0;
  for (const Eigen::Vector3d& w : world) on_table += std::abs(e.known.Distance(w)) <= 0.01;
  const fusion::PlaneCoefficients& t = e.known.plane;
  std::printf("\n## PCL stereo frame (table_scene_mug_stereo_textured): %zu points within %.1f m, "
              "%.3f m voxels\n\ntable fitted from the points: %.4f x + %.4f y + %.4f z + %.4f = 0 "
              "(%.0f %% of the points within 1 cm, rms %.1f mm, centroid %.3f %.3f %.3f); "
              "columns along %c\n\n",
              world.size(), spec.r_max_m, o.pcd_resolution_m, t[0], t[1], t[2], t[3],
              100.0 * on_table / std::max<std::size_t>(1, world.size()), 1000.0 * rms_m,
              e.known.centroid.x(), e.known.centroid.y(), e.known.centroid.z(), "xyz"[e.known.axis]);
  std::printf("| map | occupied voxels | holding a point | within one voxel of a point | "
              "clean-table thickness (mm) | table offset (mm) | clean table columns covered | "
              "time (s) |\n|---|---|---|---|---|---|---|---|\n");
  const auto ours = MapWithCore(spec, o.pcd_resolution_m, frames);
  if (!ours) {
    std::fprintf(stderr, "PCD: the map refused the sensor or the frame\n");
    return 1;
  }
  const double occupied_threshold = fusion::service::DefaultConfig().map().occupied_threshold();
  PrintRow("ours (stereo model of e2e_pcd_test)", ours->time_s,
           Score(OccupiedVoxels(*ours->tree, occupied_threshold), e));
  const Built octomap = MapWithOctoMap(o.pcd_resolution_m, spec.r_max_m, frames);
  PrintRow("OctoMap insertPointCloud", octomap.time_s,
           Score(OccupiedVoxels(*octomap.tree, octomap.tree->getOccupancyThres()), e));
  // The whole frame, and in front of the wall (z < 1.5 m, as e2e_pcd_test asks).
  const Eigen::AlignedBox3d front(Eigen::Vector3d(-5, -5, 0), Eigen::Vector3d(5, 5, 1.5));
  std::printf("\nplanes (FindPlanes' defaults: 2-degree bins, distance bins of the voxel edge):\n");
  PrintKnownPlanes("ours, whole frame", "table", FindKnownPlanes(*ours->tree, e.known));
  PrintKnownPlanes("ours, z < 1.5 m", "table", FindKnownPlanes(*ours->tree, e.known, front));
  PrintKnownPlanes("OctoMap, whole frame", "table", FindKnownPlanes(*octomap.tree, e.known));
  PrintKnownPlanes("OctoMap, z < 1.5 m", "table", FindKnownPlanes(*octomap.tree, e.known, front));
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  Options o;
  if (!ParseArgs(argc, argv, &o)) return 2;
  std::printf("accuracy_real: data %s\n", o.data_dir.c_str());
  if (o.Runs("tum")) {
    if (const int tum = RunTum(o); tum != 0) return tum;
  }
  if (o.Runs("scan")) {
    if (const int scan = RunScanGrid(o); scan != 0) return scan;
  }
  return o.Runs("pcd") ? RunPcd(o) : 0;
}
