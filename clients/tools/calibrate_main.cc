// fusion-calibrate: fits a sensor's forward model (q_mu, q_sigma, eps, r_min, r_max) to
// recorded clouds of a planar target and prints it as a fusiond `sensors { ... }` block.
// The maths is core's (fusion/core/calibration.h); this file reads recordings, talks, plots.
#include <google/protobuf/text_format.h>

#include <Eigen/Geometry>
#include <cmath>
#include <cstdio>
#include <memory>
#include <optional>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "calibrate_plot.h"
#include "fusion/clients/cli.h"
#include "fusion/clients/importers.h"
#include "fusion/clients/recording.h"
#include "fusion/core/calibration.h"
#include "fusion/core/sensor.h"
#include "fusion/v1/config.pb.h"

namespace {

using fusion::Status;
namespace cli = fusion::clients;

constexpr const char* kTool = "fusion-calibrate";

constexpr const char* kUsage =
    R"(fusion-calibrate: fit a sensor's forward model to recordings of a plane

Usage: fusion-calibrate RECORDING.frec... --sensor-id ID [options]
  --sensor-id ID        the sensor whose clouds are used (required)
  --plane A,B,C,D       the target, a x + b y + c z + d = 0 in the world frame (metres). The
                        true range of a reading is where its ray meets this plane. Without it
                        the dominant plane of the near-range points is fitted (RANSAC) and used
  --degree N            degree 0..2 of the bias q_mu(t) - t and of q_sigma (default 2, the
                        paper's; 1 = linear, 0 = constant)
  --r-min M --r-max M   only samples whose true range lies in [M, M] (default: all)
  --bins N              range bins of the table and of the robust start (default 12)
  --max-points N        per cloud, an even subsample of at most N points (default 20000)
  --gate M,F            a point is a reading of the plane only if |r - t| <= M + F t
                        (default 0.3,0.15: points on other surfaces are left out; the
                        stereo camera's bias is 13 % of the range)
  --min-incidence C     rays whose |cos| to the plane's normal is below C are left out
                        (default 0.2: on grazing rays a small error of the plane or the
                        pose is a large error of the true range)
  --local-patch M       the noise (q_sigma, eps) from residuals against local planes: each
                        cloud's points in M x M cells of the target (e.g. 0.05 for a depth
                        camera; a cell needs 12 points), so that the reference's error
                        (tilted poses, a warped plane) does not count as sensor noise; the
                        bias still comes from the target plane
  --preset NAME         also write `preset: NAME` (the geometry: field of view, beams)
  --plot FILE.png       residual against true range, inliers / outliers, the fitted bias
                        and its +-3 sigma band
Without --plane:
  --near M              dominant-plane candidates: points within M of the sensor (default 2)
  --plane-z-band LO,HI  ... and with a world z in [LO, HI] (e.g. a floor near z = 0)
  --plane-inlier M      RANSAC inlier distance (default 0.02)
  --fit-plane-only      print the fitted plane as A,B,C,D on stdout and stop
  --plane-per-cloud     fit each cloud's own dominant plane (when the poses are too poor to
                        share one plane; a bias common to a whole cloud is then not seen)
  --help                this text

stdout: only the `sensors { ... }` block (fusion.v1.SensorConfig in text format) to paste
into a fusiond .pbtxt: id, model, r_min_m, r_max_m (the true ranges where the data holds
inliers), q_mu, q_sigma, epsilon. stderr: progress, the plane, the per-bin table, eps, the
log-likelihood. The fit is maximum likelihood (EM) of a normal reading around q_mu(t) with
sigma q_sigma(t), plus outliers (share eps) uniform over the readings' span.
Exit status: 0 done, 1 the data cannot be fitted (unreadable recording, unknown sensor id,
too few points on the target, no target found, degenerate range spread), 2 bad command line.
)";

struct Options {
  std::vector<std::string> recordings;
  std::string sensor_id, plot_path, preset;
  std::optional<fusion::PlaneCoefficients> plane;
  std::optional<std::pair<double, double>> z_band;
  std::uint64_t degree = 2, bins = 12, max_points = 20000;
  double window_min_m = 0.0, window_max_m = fusion::CalibrationOptions::kInfinity;
  double near_m = 2.0, plane_inlier_m = 0.02, gate_m = 0.3, gate_fraction = 0.15;
  double min_incidence_cos = 0.2, local_patch_m = 0.0;
  bool fit_plane_only = false, plane_per_cloud = false;
};

Status ParseList(const std::string& flag, const std::string& text, std::size_t count,
                 std::vector<double>* values) {
  std::stringstream stream(text);
  values->clear();
  for (std::string item; std::getline(stream, item, ',');) {
    double v = 0.0;
    if (Status s = cli::ParseDouble(flag, item, &v); !s.ok()) return s;
    values->push_back(v);
  }
  if (values->size() != count) {
    return Status::Error(flag + ": expected " + std::to_string(count) +
                         " comma-separated numbers, got '" + text + "'");
  }
  return Status::Ok();
}

// The option `arg` taking value `v`; false if `arg` is none.
bool ApplyValue(const std::string& arg, const std::string& v, Options* o, Status* s) {
  std::vector<double> list;
  if (arg == "--sensor-id") {
    o->sensor_id = v;
  } else if (arg == "--plot") {
    o->plot_path = v;
  } else if (arg == "--preset") {
    o->preset = v;
    if (!fusion::SensorPreset(v)) *s = Status::Error("--preset: '" + v + "' is not a preset");
  } else if (arg == "--plane") {
    *s = ParseList(arg, v, 4, &list);
    if (s->ok() && !(std::hypot(list[0], list[1], list[2]) > 0.0)) {
      *s = Status::Error("--plane: the normal (A, B, C) must not be zero");
    }
    if (s->ok()) o->plane = fusion::PlaneCoefficients(list[0], list[1], list[2], list[3]);
  } else if (arg == "--plane-z-band") {
    *s = ParseList(arg, v, 2, &list);
    if (s->ok() && !(list[0] < list[1])) *s = Status::Error("--plane-z-band: LO must be < HI");
    if (s->ok()) o->z_band = std::make_pair(list[0], list[1]);
  } else if (arg == "--gate") {
    *s = ParseList(arg, v, 2, &list);
    if (s->ok() && !(list[0] >= 0.0 && list[1] >= 0.0)) *s = Status::Error("--gate: M, F >= 0");
    if (s->ok()) o->gate_m = list[0], o->gate_fraction = list[1];
  } else if (arg == "--degree" || arg == "--bins" || arg == "--max-points") {
    std::uint64_t* n = arg == "--degree" ? &o->degree : arg == "--bins" ? &o->bins : &o->max_points;
    *s = cli::ParseUint(arg, v, n);
    if (s->ok() && arg == "--degree" && *n > 2) *s = Status::Error("--degree must be 0, 1 or 2");
    if (s->ok() && arg != "--degree" && (*n < 1 || *n > 100000000)) {
      *s = Status::Error(arg + " must be in 1..100000000");
    }
  } else if (arg == "--r-min" || arg == "--r-max" || arg == "--near" || arg == "--plane-inlier" ||
             arg == "--min-incidence" || arg == "--local-patch") {
    double* d = arg == "--r-min"           ? &o->window_min_m
                : arg == "--local-patch"   ? &o->local_patch_m
                : arg == "--r-max"         ? &o->window_max_m
                : arg == "--near"          ? &o->near_m
                : arg == "--min-incidence" ? &o->min_incidence_cos
                                           : &o->plane_inlier_m;
    *s = cli::ParseDouble(arg, v, d);
    if (s->ok() && *d < 0.0) *s = Status::Error(arg + " must be >= 0");
    if (s->ok() && arg == "--local-patch" && !(*d > 0.0)) {
      *s = Status::Error("--local-patch must be > 0 (the cell edge in metres)");
    }
    if (s->ok() && arg == "--min-incidence" && *d >= 1.0) {
      *s = Status::Error("--min-incidence must be below 1");
    }
  } else {
    return false;
  }
  return true;
}

std::optional<int> ParseFlags(int argc, char** argv, Options* o) {
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    if (cli::IsHelpFlag(arg)) return cli::PrintHelp(kUsage);
    if (arg == "--fit-plane-only" || arg == "--plane-per-cloud") {
      (arg == "--fit-plane-only" ? o->fit_plane_only : o->plane_per_cloud) = true;
      continue;
    }
    if (arg.size() > 1 && arg[0] == '-') {
      std::string value;
      Status s;
      if (!cli::TakeValue(argc, argv, &i, &value)) {
        return cli::UsageError(kTool, arg + " needs a value or is not an option");
      }
      if (!ApplyValue(arg, value, o, &s)) return cli::UsageError(kTool, "unknown option " + arg);
      if (!s.ok()) return cli::UsageError(kTool, s.message());
      continue;
    }
    o->recordings.push_back(arg);
  }
  if (o->recordings.empty()) return cli::UsageError(kTool, "no recording given");
  if (o->sensor_id.empty()) return cli::UsageError(kTool, "--sensor-id is required");
  if (!(o->window_min_m < o->window_max_m)) {
    return cli::UsageError(kTool, "--r-min must be below --r-max");
  }
  if ((o->fit_plane_only || o->plane_per_cloud) && o->plane) {
    return cli::UsageError(kTool,
                           "--fit-plane-only and --plane-per-cloud fit the plane: "
                           "leave out --plane");
  }
  if (o->fit_plane_only && o->plane_per_cloud) {
    return cli::UsageError(kTool, "--fit-plane-only fits one plane for all clouds");
  }
  return std::nullopt;
}

Eigen::Isometry3d PoseOf(const fusion::v1::RecordedPose& p) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = Eigen::Quaterniond(p.qw(), p.qx(), p.qy(), p.qz()).normalized().toRotationMatrix();
  T.translation() = Eigen::Vector3d(p.tx(), p.ty(), p.tz());
  return T;
}

// Every cloud of the sensor in the recordings, its points evenly subsampled to max_points, in
// order; progress on stderr for long inputs.
class CloudSource {
 public:
  Status Open(const Options& o) {
    options_ = &o;
    for (const std::string& path : o.recordings) {
      std::unique_ptr<cli::RecordingReader> reader;
      if (Status s = cli::RecordingReader::Open(path, &reader); !s.ok()) {
        return s.WithContext("reading " + path);
      }
      for (std::size_t i = 0; i < reader->size(); ++i) {
        ids_.insert(reader->entry(i).sensor_id());
        total_ += reader->entry(i).sensor_id() == o.sensor_id;
      }
      readers_.push_back(std::move(reader));
    }
    if (total_ == 0) {
      std::string known;
      for (const std::string& id : ids_) known += (known.empty() ? "" : ", ") + id;
      return Status::Error("unknown sensor id '" + o.sensor_id + "': the recordings hold " +
                           (known.empty() ? "no clouds" : "clouds of " + known));
    }
    return Status::Ok();
  }

  // visit(points_xyz, count, T_world_sensor) for each cloud.
  template <class Visit>
  Status ForEach(const char* what, const Visit& visit) {
    std::size_t done = 0;
    const std::size_t every = std::max<std::size_t>(1, total_ / 10);
    fusion::v1::RecordedCloud cloud;
    std::vector<float> points;
    for (std::size_t r = 0; r < readers_.size(); ++r) {
      for (std::size_t i = 0; i < readers_[r]->size(); ++i) {
        if (readers_[r]->entry(i).sensor_id() != options_->sensor_id) continue;
        if (Status s = readers_[r]->Read(i, &cloud); !s.ok()) {
          return s.WithContext("reading " + options_->recordings[r]);
        }
        Subsample(cloud, &points);
        visit(points.data(), points.size() / 3, PoseOf(cloud.t_world_sensor()));
        if (++done % every == 0 && total_ >= 20) {
          std::fprintf(stderr, "%s: %s: %zu / %zu clouds\n", kTool, what, done, total_);
        }
      }
    }
    return Status::Ok();
  }
  [[nodiscard]] std::size_t total() const { return total_; }

 private:
  void Subsample(const fusion::v1::RecordedCloud& cloud, std::vector<float>* points) const {
    const std::size_t n = cloud.xyz_f32le().size() / 12;
    const std::size_t stride =
        std::max<std::size_t>(1, (n + options_->max_points - 1) / options_->max_points);
    points->clear();
    for (std::size_t i = 0; i < n; i += stride) {
      float p[3];
      cli::GetPoint(cloud, i, p);
      points->insert(points->end(), p, p + 3);
    }
  }

  const Options* options_ = nullptr;
  std::vector<std::unique_ptr<cli::RecordingReader>> readers_;
  std::set<std::string> ids_;
  std::size_t total_ = 0;
};

std::string PlaneText(const fusion::PlaneCoefficients& p) {
  char text[128];
  std::snprintf(text, sizeof text, "%.6f,%.6f,%.6f,%.6f", p[0], p[1], p[2], p[3]);
  return text;
}

// The dominant-plane candidates of one cloud: points within --near, in the --plane-z-band.
void AppendCandidates(const Options& o, const float* xyz, std::size_t n,
                      const Eigen::Isometry3d& T_world_sensor,
                      std::vector<Eigen::Vector3d>* candidates) {
  std::vector<Eigen::Vector3d> near;
  fusion::AppendNearPointsWorld(xyz, n, T_world_sensor, o.near_m, &near);
  for (const Eigen::Vector3d& p : near) {
    if (o.z_band && (p.z() < o.z_band->first || p.z() > o.z_band->second)) continue;
    candidates->push_back(p);
  }
}

fusion::PlaneFit FitCandidates(const Options& o, const std::vector<Eigen::Vector3d>& candidates) {
  fusion::PlaneFitOptions options;
  options.inlier_distance_m = o.plane_inlier_m;
  return fusion::FitDominantPlane(candidates, options);
}

std::string CandidateText(const Options& o) {
  char text[160];
  std::snprintf(text, sizeof text, "points within %g m of the sensor", o.near_m);
  std::string where = text;
  if (o.z_band) {
    std::snprintf(text, sizeof text, " with world z in [%g, %g] m", o.z_band->first,
                  o.z_band->second);
    where += text;
  }
  return where;
}

Status FitPlane(const Options& o, CloudSource* source, fusion::PlaneCoefficients* plane) {
  std::vector<Eigen::Vector3d> candidates;
  Status s = source->ForEach(
      "plane fit", [&](const float* xyz, std::size_t n, const Eigen::Isometry3d& T_world_sensor) {
        AppendCandidates(o, xyz, n, T_world_sensor, &candidates);
      });
  if (!s.ok()) return s;
  const fusion::PlaneFit fit = FitCandidates(o, candidates);
  if (!fit.ok()) return Status::Error(fit.error);
  std::fprintf(stderr,
               "%s: no --plane: fitted the dominant plane of %zu %s: --plane %s (%zu inliers "
               "within %.3f m, rms %.4f m)\n",
               kTool, fit.points, CandidateText(o).c_str(), PlaneText(fit.plane).c_str(),
               fit.inliers, o.plane_inlier_m, fit.rms_m);
  *plane = fit.plane;
  return Status::Ok();
}

double Rounded(double v) {  // 7 significant digits: enough for a model, short to read
  char text[32];
  std::snprintf(text, sizeof text, "%.7g", v);
  return std::stod(text);
}

void SetPolynomial(const fusion::Polynomial2& p, fusion::v1::Polynomial2* out) {
  out->set_a2(Rounded(p.a2));
  out->set_a1(Rounded(p.a1));
  out->set_a0(Rounded(p.a0));
}

constexpr double kEpsilonFloor = 1e-4;

std::string SensorBlock(const Options& o, const fusion::Calibration& fit) {
  fusion::v1::SensorConfig config;
  config.set_id(o.sensor_id);
  if (!o.preset.empty()) config.set_preset(o.preset);
  config.set_model("paper3d");
  config.set_r_min_m(std::round(fit.r_min_m * 1000.0) / 1000.0);
  config.set_r_max_m(std::round(fit.r_max_m * 1000.0) / 1000.0);
  SetPolynomial(fit.q_mu, config.mutable_q_mu());
  SetPolynomial(fit.q_sigma, config.mutable_q_sigma());
  config.set_epsilon(Rounded(std::max(kEpsilonFloor, fit.epsilon)));
  google::protobuf::TextFormat::Printer printer;
  printer.SetInitialIndentLevel(1);
  std::string body;
  printer.PrintToString(config, &body);
  return "sensors {\n" + body + "}\n";
}

void Report(const fusion::Calibration& fit, const fusion::PlaneSampleStats& stats) {
  std::fprintf(stderr,
               "%s: %zu points: %zu samples on the plane, %zu missing, %zu rays nearly "
               "parallel to it, %zu with the plane behind, %zu gated out (other surfaces)\n",
               kTool, stats.points, stats.samples, stats.missing, stats.parallel, stats.behind,
               stats.gated);
  std::fprintf(stderr,
               "%s: range bins (true range t; bias = mean(r - t), sigma = std(r - q_mu(t)) of "
               "the inliers; fitted at the bin centre; mm):\n",
               kTool);
  std::fprintf(stderr, "  %-15s %9s %9s %9s %10s %10s %10s %10s\n", "t (m)", "count", "inliers",
               "outliers", "bias", "sigma", "fit bias", "fit sigma");
  for (const fusion::CalibrationBin& b : fit.bins) {
    std::fprintf(stderr, "  %6.3f - %6.3f %9zu %9zu %9zu %10.1f %10.1f %10.1f %10.1f\n", b.begin_m,
                 b.end_m, b.count, b.inliers, b.outliers, 1000.0 * b.measured_bias_m,
                 1000.0 * b.measured_sigma_m, 1000.0 * b.fitted_bias_m, 1000.0 * b.fitted_sigma_m);
  }
  std::fprintf(stderr,
               "%s: q_mu = %.7g t^2 + %.7g t + %.7g, q_sigma = %.7g t^2 + %.7g t + %.7g (m), "
               "eps %.5f%s, inliers at t in [%.3f, %.3f] m\n",
               kTool, fit.q_mu.a2, fit.q_mu.a1, fit.q_mu.a0, fit.q_sigma.a2, fit.q_sigma.a1,
               fit.q_sigma.a0, fit.epsilon,
               fit.epsilon < kEpsilonFloor ? " (written as 1e-4: a floor, so that no single "
                                             "reading is final)"
                                           : "",
               fit.r_min_m, fit.r_max_m);
  std::fprintf(stderr,
               "%s: log-likelihood %.1f nats over %zu samples (%.4f per sample), %zu inliers, "
               "EM %s after %d iterations\n",
               kTool, fit.log_likelihood, fit.samples,
               fit.log_likelihood / static_cast<double>(fit.samples), fit.inliers,
               fit.converged ? "converged" : "stopped (not converged)", fit.iterations);
}

// --local-patch: the local samples' residuals about the reference's bias, as the plot shows
// them (the band is then the sensor's noise about its bias).
std::vector<fusion::RangeSample> LocalPlotted(const std::vector<fusion::RangeSample>& local,
                                              const fusion::Polynomial2& q_mu) {
  std::vector<fusion::RangeSample> out = local;
  for (fusion::RangeSample& s : out) s.reading_m += q_mu(s.true_range_m) - s.true_range_m;
  return out;
}

void ReportLocal(const Options& o, const fusion::LocalSampleStats& stats,
                 const fusion::Calibration& reference, const fusion::Calibration& local) {
  std::fprintf(stderr,
               "%s: --local-patch %.3f: %zu local samples in %zu cells (%zu points in cells "
               "with too few left out); against the target plane alone sigma would be "
               "%.1f / %.1f mm at %.2f / %.2f m, against local planes %.1f / %.1f mm, eps %.5f "
               "against %.5f (the table's sigma columns: the local fit's)\n",
               kTool, o.local_patch_m, stats.plane.samples, stats.cells, stats.sparse,
               1000.0 * reference.q_sigma(reference.r_min_m),
               1000.0 * reference.q_sigma(reference.r_max_m), reference.r_min_m, reference.r_max_m,
               1000.0 * local.q_sigma(reference.r_min_m), 1000.0 * local.q_sigma(reference.r_max_m),
               local.epsilon, reference.epsilon);
}

struct Samples {
  std::vector<fusion::RangeSample> samples;
  fusion::PlaneSampleStats stats;
  std::vector<fusion::RangeSample> local_samples;  // --local-patch
  fusion::LocalSampleStats local_stats;
};

void Add(const fusion::PlaneSampleStats& cloud, fusion::PlaneSampleStats* stats) {
  stats->points += cloud.points, stats->missing += cloud.missing;
  stats->parallel += cloud.parallel, stats->behind += cloud.behind;
  stats->gated += cloud.gated, stats->samples += cloud.samples;
}

// The samples of every cloud against `plane`, or (--plane-per-cloud) against each cloud's own
// dominant plane; clouds without one are left out, all of them without one is an error.
Status CollectSamples(const Options& o, CloudSource* source, fusion::PlaneCoefficients plane,
                      Samples* out) {
  fusion::PlaneSampleOptions sample_options;
  sample_options.max_residual_m = o.gate_m;
  sample_options.max_residual_fraction = o.gate_fraction;
  sample_options.min_incidence_cos = o.min_incidence_cos;
  std::size_t cloud_index = 0, clouds_without_plane = 0;
  std::string plane_error;
  Status s = source->ForEach("samples", [&](const float* xyz, std::size_t n,
                                            const Eigen::Isometry3d& T_world_sensor) {
    ++cloud_index;
    if (o.plane_per_cloud) {
      std::vector<Eigen::Vector3d> candidates;
      AppendCandidates(o, xyz, n, T_world_sensor, &candidates);
      const fusion::PlaneFit fit = FitCandidates(o, candidates);
      if (!fit.ok()) {
        ++clouds_without_plane;
        plane_error = fit.error;
        return;
      }
      plane = fit.plane;
      if (source->total() <= 20) {
        std::fprintf(stderr, "%s: cloud %zu: plane %s (%zu of %zu inliers, rms %.4f m)\n", kTool,
                     cloud_index, PlaneText(plane).c_str(), fit.inliers, fit.points, fit.rms_m);
      }
    }
    Add(fusion::AppendPlaneSamples(xyz, n, T_world_sensor, plane, sample_options, &out->samples),
        &out->stats);
    if (o.local_patch_m > 0.0) {
      fusion::LocalPlaneOptions local;
      local.patch_m = o.local_patch_m;
      const auto cloud = fusion::AppendLocalPlaneSamples(xyz, n, T_world_sensor, plane,
                                                         sample_options, local,
                                                         &out->local_samples);
      Add(cloud.plane, &out->local_stats.plane);
      out->local_stats.cells += cloud.cells, out->local_stats.sparse += cloud.sparse;
    }
  });
  if (!s.ok()) return s;
  if (clouds_without_plane == source->total()) return Status::Error(plane_error);
  if (clouds_without_plane > 0) {
    std::fprintf(stderr, "%s: %zu of %zu clouds have no dominant plane (%s): left out\n", kTool,
                 clouds_without_plane, source->total(), plane_error.c_str());
  }
  if (out->stats.samples == 0 && !o.plane_per_cloud) {
    return Status::Error("no target found: no point of the " + std::to_string(out->stats.points) +
                         " lies on the plane " + PlaneText(plane));
  }
  return Status::Ok();
}

int Run(const Options& o) {
  CloudSource source;
  if (Status s = source.Open(o); !s.ok()) return cli::Fail(kTool, s.message());
  std::fprintf(stderr, "%s: %zu clouds of sensor '%s'\n", kTool, source.total(),
               o.sensor_id.c_str());
  fusion::PlaneCoefficients plane = fusion::PlaneCoefficients::Zero();
  if (o.plane_per_cloud) {
    std::fprintf(stderr, "%s: --plane-per-cloud: each cloud's own dominant plane of the %s\n",
                 kTool, CandidateText(o).c_str());
  } else if (o.plane) {
    plane = fusion::NormalizedPlane(*o.plane);
    std::fprintf(stderr, "%s: target plane (world frame) %s\n", kTool, PlaneText(plane).c_str());
  } else if (Status s = FitPlane(o, &source, &plane); !s.ok()) {
    return cli::Fail(kTool, s.message());
  }
  if (o.fit_plane_only) {
    std::printf("%s\n", PlaneText(plane).c_str());
    return cli::kExitOk;
  }
  Samples got;
  if (Status s = CollectSamples(o, &source, plane, &got); !s.ok()) {
    return cli::Fail(kTool, s.message());
  }
  const std::vector<fusion::RangeSample>& samples = got.samples;
  const fusion::PlaneSampleStats& stats = got.stats;
  fusion::CalibrationOptions options;
  options.degree = static_cast<int>(o.degree);
  options.bins = static_cast<int>(o.bins);
  options.window_min_m = o.window_min_m;
  options.window_max_m = o.window_max_m;
  fusion::Calibration fit = fusion::CalibrateForwardModel(samples, options);
  if (!fit.ok()) return cli::Fail(kTool, fit.error);
  std::vector<fusion::RangeSample> plotted = samples;
  if (o.local_patch_m > 0.0) {
    const fusion::Calibration local = fusion::CalibrateForwardModel(got.local_samples, options);
    if (!local.ok()) {
      return cli::Fail(kTool, "--local-patch: " + local.error + " (" +
                                  std::to_string(got.local_stats.sparse) +
                                  " points lay in cells too sparse for a local plane: sparse "
                                  "clouds need larger cells)");
    }
    ReportLocal(o, got.local_stats, fit, local);
    plotted = LocalPlotted(got.local_samples, fit.q_mu);
    fit = fusion::WithLocalNoise(fit, local);
    fit.inlier_responsibility = local.inlier_responsibility;  // the plot's colours, per `plotted`
  }
  Report(fit, stats);
  if (!o.plot_path.empty()) {
    std::string error;
    char title[160];
    std::snprintf(title, sizeof title, "fusion-calibrate %s: %zu samples%s, eps %.2g",
                  o.sensor_id.c_str(), plotted.size(),
                  o.local_patch_m > 0.0 ? " (local residuals about the bias)" : "", fit.epsilon);
    if (!fusion::clients::WriteCalibrationPlot(o.plot_path, plotted, fit, title, &error)) {
      return cli::Fail(kTool, "--plot: " + error);
    }
    std::fprintf(stderr, "%s: plot written to %s\n", kTool, o.plot_path.c_str());
  }
  std::fputs(SensorBlock(o, fit).c_str(), stdout);
  return cli::kExitOk;
}

}  // namespace

int main(int argc, char** argv) {
  Options options;
  if (const std::optional<int> done = ParseFlags(argc, argv, &options)) return *done;
  return Run(options);
}
