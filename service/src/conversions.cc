// Wire <-> core conversions: the only place that knows both sides.
#include "fusion/service/conversions.h"

#include <algorithm>
#include <cmath>
#include <string>
#include <thread>

namespace fusion::service {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kDegToRad = kPi / 180.0;

bool Finite(const Eigen::Vector3d& v) { return v.allFinite(); }

Polynomial2 PolynomialFromConfig(const fusion::v1::Polynomial2& p) {
  return {p.a2(), p.a1(), p.a0()};
}

// A WorldMapOptions::IsValid message (which starts with core's field path) as the MapConfig
// field behind it and what to say: degrees in the file, radians in core; the beam and render
// options flattened; a 0 in the file that core never sees explained.
std::string MapConfigError(const std::string& why) {
  struct Field {
    const char* core;
    const char* config;
    const char* note;
  };
  static const Field kFields[] = {
      {"pose_tolerance_rad", "pose_tolerance_deg", ""},
      {"beam_grid.cell_size_m", "beam_cell_size_m", ""},
      {"beam_grid.change_run", "change_detection_run", ""},
      {"beam_grid.change_min_mass", "change_detection_min_mass", ""},
      {"render.max_range_m", "max_range_m", " (0: each sensor's full range)"},
      {"render.threads", "render_threads", " (0: one fewer than the hardware threads, at least 1)"},
      {"occupancy_threshold", "occupied_threshold", ""},
      {"history_clamping_max_probability", "history_clamping_max", ""},
  };
  const std::string core_field = why.substr(0, why.find(' '));
  for (const Field& f : kFields) {
    if (core_field == f.core) return std::string(f.config) + ": " + why + f.note;
  }
  // The same name in both (resolution_m, pose_tolerance_m), or a field the file cannot set.
  return core_field + ":" + why.substr(core_field.size());
}

}  // namespace

Eigen::Isometry3d IsometryFromConfig(const fusion::v1::Transform& t) {
  Eigen::Quaterniond q(t.qw(), t.qx(), t.qy(), t.qz());
  if (q.coeffs().isZero()) q = Eigen::Quaterniond::Identity();
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = q.normalized().toRotationMatrix();
  T.translation() = Eigen::Vector3d(t.tx(), t.ty(), t.tz());
  return T;
}

namespace {

// A pinhole block that gives the camera's intrinsics (not only a stride).
bool GivesIntrinsics(const fusion::v1::PinholeConfig& p) {
  return p.fx() != 0.0 || p.fy() != 0.0 || p.width() != 0 || p.height() != 0;
}

// The sensor's geometry and noise: a preset's, or every field given (a camera whose intrinsics
// come from its CameraInfo has no geometry to give).
StatusOr<SensorSpec> BaseSpecFromConfig(const fusion::v1::SensorConfig& c, bool from_camera_info) {
  if (!c.preset().empty()) {
    auto preset = SensorPreset(c.preset());
    if (!preset) {
      std::string names;
      for (const auto& n : SensorPresetNames()) names += (names.empty() ? "" : ", ") + n;
      return Status::Error("preset: '" + c.preset() + "' is not a known preset (" + names + ")");
    }
    return *preset;
  }
  const bool angular = !c.has_pinhole() && !from_camera_info;
  const char* missing = !c.has_r_min_m()                                       ? "r_min_m"
                        : !c.has_r_max_m()                                     ? "r_max_m"
                        : angular && !c.has_fov_h_deg() && !c.has_azimuth_min_deg() ? "fov_h_deg"
                        : angular && !c.has_fov_v_deg() && !c.has_elevation_min_deg()
                            ? "fov_v_deg"
                        : angular && !c.has_cols() ? "cols"
                        : angular && !c.has_rows() ? "rows"
                        : !c.has_q_mu()            ? "q_mu"
                        : !c.has_q_sigma()         ? "q_sigma"
                                                   : nullptr;
  if (missing != nullptr) {
    return Status::Error(std::string(missing) + ": required when no preset is given" +
                         (angular ? " (or a pinhole block)" : ""));
  }
  return SensorSpec{};
}

// Width, height and stride of a pinhole block fit a beam grid's int indices with room to spare.
Status CheckPixelCounts(std::uint32_t width, std::uint32_t height, std::uint32_t stride) {
  constexpr std::uint32_t kMaxPixels = 1u << 16;
  if (width > kMaxPixels || height > kMaxPixels || stride > kMaxPixels) {
    return Status::Error("pinhole: width, height and stride must be at most 65536");
  }
  return Status::Ok();
}

// A pinhole block over `spec`: the full intrinsics, or only a stride over a pinhole preset.
Status ApplyPinhole(const fusion::v1::PinholeConfig& p, SensorSpec* spec) {
  if (Status s = CheckPixelCounts(p.width(), p.height(), p.stride()); !s.ok()) return s;
  PinholeIntrinsics k;
  if (GivesIntrinsics(p)) {
    k = {p.fx(), p.fy(), p.cx(), p.cy(), static_cast<int>(p.width()),
         static_cast<int>(p.height()), 1};
  } else if (spec->pinhole) {
    k = *spec->pinhole;
  } else {
    return Status::Error("pinhole: fx, fy, cx, cy, width and height are required (only the "
                         "stride may be given alone, over a pinhole preset)");
  }
  k.stride = static_cast<int>(std::max<std::uint32_t>(1, p.stride()));
  SetPinhole(k, spec);
  return Status::Ok();
}

// The intrinsics a camera waiting for its CameraInfo is checked with: the other fields must
// make a valid spec with some camera (ValidateSensorSpec); its beams come later
// (SpecFromCameraInfo).
constexpr PinholeIntrinsics kNominalCamera{1.0, 1.0, 0.0, 0.0, 1, 1, 1};

// A depth_image sensor without configured intrinsics: no angular fields, at most a stride.
Status ApplyCameraInfoGeometry(const fusion::v1::SensorConfig& c, bool angular, SensorSpec* spec) {
  if (angular) {
    return Status::Error(
        "pinhole: a depth image's beams are its pixels (from its CameraInfo, "
        "or a pinhole block); the angular fields (fov_*, azimuth / elevation "
        "limits, cols, rows) do not apply");
  }
  PinholeIntrinsics k = kNominalCamera;
  if (Status s = CheckPixelCounts(0, 0, c.pinhole().stride()); !s.ok()) return s;
  k.stride = static_cast<int>(std::max<std::uint32_t>(1, c.pinhole().stride()));
  SetPinhole(k, spec);
  return Status::Ok();
}

// The angular field of view and beams the file sets: symmetric widths or the limits of an
// asymmetric one, cols and rows; a pinhole block instead of all of them.
Status ApplyGeometry(const fusion::v1::SensorConfig& c, bool from_camera_info, SensorSpec* spec) {
  const bool az = c.has_azimuth_min_deg() || c.has_azimuth_max_deg();
  const bool el = c.has_elevation_min_deg() || c.has_elevation_max_deg();
  if (az && !(c.has_azimuth_min_deg() && c.has_azimuth_max_deg())) {
    return Status::Error("azimuth_min_deg: give azimuth_min_deg and azimuth_max_deg together");
  }
  if (el && !(c.has_elevation_min_deg() && c.has_elevation_max_deg())) {
    return Status::Error("elevation_min_deg: give elevation_min_deg and elevation_max_deg together");
  }
  if (az && c.has_fov_h_deg()) {
    return Status::Error("fov_h_deg: give fov_h_deg or azimuth_min_deg / azimuth_max_deg, not both");
  }
  if (el && c.has_fov_v_deg()) {
    return Status::Error("fov_v_deg: give fov_v_deg or elevation_min_deg / elevation_max_deg, not both");
  }
  const bool h = az || c.has_fov_h_deg(), v = el || c.has_fov_v_deg();
  const bool angular = h || v || c.has_cols() || c.has_rows();
  if (from_camera_info) return ApplyCameraInfoGeometry(c, angular, spec);
  if (c.has_pinhole()) {
    if (angular) {
      return Status::Error("pinhole: a camera's beams follow from its intrinsics; give pinhole or "
                           "the angular fields (fov_*, azimuth / elevation limits, cols, rows)");
    }
    return ApplyPinhole(c.pinhole(), spec);
  }
  if (!angular) return Status::Ok();
  if (spec->pinhole) {
    if (!(h && v && c.has_cols() && c.has_rows())) {
      return Status::Error("cols: over a pinhole preset an angular grid needs its field of view, "
                           "cols and rows");
    }
    spec->pinhole.reset();
  }
  if (c.has_fov_h_deg()) {
    spec->fov_h_rad = c.fov_h_deg() * kDegToRad;
    spec->azimuth_centre_rad = 0.0;
  }
  if (c.has_fov_v_deg()) {
    spec->fov_v_rad = c.fov_v_deg() * kDegToRad;
    spec->elevation_centre_rad = 0.0;
  }
  if (az) {
    spec->fov_h_rad = (c.azimuth_max_deg() - c.azimuth_min_deg()) * kDegToRad;
    spec->azimuth_centre_rad = 0.5 * (c.azimuth_min_deg() + c.azimuth_max_deg()) * kDegToRad;
  }
  if (el) {
    spec->fov_v_rad = (c.elevation_max_deg() - c.elevation_min_deg()) * kDegToRad;
    spec->elevation_centre_rad = 0.5 * (c.elevation_min_deg() + c.elevation_max_deg()) * kDegToRad;
  }
  if (c.has_cols()) spec->cols = static_cast<int>(std::min<std::uint32_t>(c.cols(), 1u << 30));
  if (c.has_rows()) spec->rows = static_cast<int>(std::min<std::uint32_t>(c.rows(), 1u << 30));
  return Status::Ok();
}

// Core's checks on a spec and a bound on its beams, named as the file's fields.
Status CheckSpec(const fusion::v1::SensorConfig& c, const SensorSpec& spec) {
  const long long beams = static_cast<long long>(spec.cols) * spec.rows;
  if (beams > 4'000'000) {
    return Status::Error("cols: cols * rows = " + std::to_string(beams) +
                         " beams is more than 4000000");
  }
  const std::string spec_error = ValidateSensorSpec(spec);
  if (spec_error.empty()) return Status::Ok();
  // Name the configuration field, not core's: degrees in the file, radians in core.
  std::string field = spec_error.substr(0, spec_error.find(' '));
  if (field == "fov_h_rad") field = "fov_h_deg";
  if (field == "fov_v_rad") field = "fov_v_deg";
  if (field == "azimuth_centre_rad") field = c.has_azimuth_min_deg() ? "azimuth_min_deg" : "fov_h_deg";
  if (field == "elevation_centre_rad") {
    field = c.has_elevation_min_deg() ? "elevation_min_deg" : "fov_v_deg";
  }
  return Status::Error(field + ": " + spec_error);
}

// The fields the file sets over the base spec, then core's checks, named as the file's fields.
Status ApplySpecFields(const fusion::v1::SensorConfig& c, bool from_camera_info, SensorSpec* spec) {
  if (spec->name.empty()) spec->name = c.id();
  if (c.model() == "classic_beam") {
    spec->model = ForwardModelKind::kClassicBeam;
  } else if (c.model() == "paper3d") {
    spec->model = ForwardModelKind::kPaper3d;
  } else if (!c.model().empty()) {
    return Status::Error("model: '" + c.model() + "' is not paper3d or classic_beam");
  }
  if (c.has_r_min_m()) spec->r_min_m = c.r_min_m();
  if (c.has_r_max_m()) spec->r_max_m = c.r_max_m();
  if (Status s = ApplyGeometry(c, from_camera_info, spec); !s.ok()) return s;
  if (c.has_q_mu()) spec->q_mu = PolynomialFromConfig(c.q_mu());
  if (c.has_q_sigma()) spec->q_sigma = PolynomialFromConfig(c.q_sigma());
  if (c.has_epsilon()) spec->epsilon = c.epsilon();
  if (c.has_beam_prior_length_m()) spec->beam_prior_length_m = c.beam_prior_length_m();
  return CheckSpec(c, *spec);
}

// A camera waiting for its CameraInfo keeps its stride and no beams (cols = rows = 0).
void AwaitCameraInfo(SensorSetup* setup) {
  setup->intrinsics_from_camera_info = true;
  setup->camera_stride = setup->spec.pinhole->stride;
  setup->spec.pinhole.reset();
  setup->spec.cols = setup->spec.rows = 0;
  setup->spec.fov_h_rad = setup->spec.fov_v_rad = 0.0;
  setup->spec.azimuth_centre_rad = setup->spec.elevation_centre_rad = 0.0;
}

// The mount and the queue: what the service adds to core's spec.
Status ApplyServiceFields(const fusion::v1::SensorConfig& c, SensorSetup* setup) {
  if (c.has_mount()) {
    const auto& m = c.mount();
    const Eigen::Vector4d q(m.qx(), m.qy(), m.qz(), m.qw());
    if (!Finite(Eigen::Vector3d(m.tx(), m.ty(), m.tz())) || !q.allFinite() ||
        (!q.isZero() && std::abs(q.norm() - 1.0) > 1e-3)) {
      return Status::Error("mount: translation must be finite and the quaternion unit (or all zero)");
    }
    setup->T_published_sensor = IsometryFromConfig(m);
  }
  if (c.has_queue_depth()) {
    if (c.queue_depth() < 1 || c.queue_depth() > 1000) {
      return Status::Error("queue_depth: " + std::to_string(c.queue_depth()) + " is outside 1..1000");
    }
    setup->queue_depth = c.queue_depth();
  }
  return Status::Ok();
}

}  // namespace

StatusOr<SensorSetup> SensorSetupFromConfig(const fusion::v1::SensorConfig& c) {
  if (c.id().empty()) return Status::Error("id: must not be empty");
  const std::optional<SensorSpec> preset = SensorPreset(c.preset());
  // A depth image without intrinsics in the file or its preset: they come from its CameraInfo.
  const bool from_camera_info = c.ros2_type() == "depth_image" && !GivesIntrinsics(c.pinhole()) &&
                                !(preset && preset->pinhole);
  auto spec = BaseSpecFromConfig(c, from_camera_info);
  if (!spec.ok()) return spec.status();
  SensorSetup setup;
  setup.id = c.id();
  setup.preset = c.preset();
  setup.spec = std::move(*spec);
  if (Status s = ApplySpecFields(c, from_camera_info, &setup.spec); !s.ok()) return s;
  if (Status s = ApplyServiceFields(c, &setup); !s.ok()) return s;
  if (from_camera_info) AwaitCameraInfo(&setup);
  return setup;
}

StatusOr<SensorSpec> SpecFromCameraInfo(const SensorSetup& setup, const ros2::CameraInfo& info) {
  fusion::v1::PinholeConfig pinhole;
  pinhole.set_fx(info.k[0]);
  pinhole.set_fy(info.k[4]);
  pinhole.set_cx(info.k[2]);
  pinhole.set_cy(info.k[5]);
  pinhole.set_width(info.width);
  pinhole.set_height(info.height);
  pinhole.set_stride(static_cast<std::uint32_t>(setup.camera_stride));
  SensorSpec spec = setup.spec;
  if (!GivesIntrinsics(pinhole)) {
    return Status::Error("CameraInfo: K and the image size are all zero (an uncalibrated camera)");
  }
  if (Status s = ApplyPinhole(pinhole, &spec); !s.ok()) return s.WithContext("CameraInfo");
  if (Status s = CheckSpec(fusion::v1::SensorConfig(), spec); !s.ok()) {
    return s.WithContext("CameraInfo");
  }
  return spec;
}

StatusOr<WorldMapOptions> WorldMapOptionsFromConfig(const fusion::v1::MapConfig& c) {
  WorldMapOptions options;
  options.resolution_m = c.resolution_m();
  const auto rule = FusionRuleFromName(c.fusion_rule());
  if (!rule) {
    std::string names;
    for (const auto& n : FusionRuleNames()) names += (names.empty() ? "" : ", ") + n;
    return Status::Error("fusion_rule: '" + c.fusion_rule() + "' is not one of " + names);
  }
  options.rule = *rule;
  options.pose_tolerance_m = c.pose_tolerance_m();
  options.pose_tolerance_rad = c.pose_tolerance_deg() * kDegToRad;
  options.beam_grid.cell_size_m = c.beam_cell_size_m();
  options.beam_grid.change_run = c.change_detection_run();
  options.beam_grid.change_min_mass = c.change_detection_min_mass();
  options.history_clamping_max_probability = c.history_clamping_max();
  options.forget_half_life_s = c.forget_half_life_s();
  options.beam_prior_length_m = c.beam_prior_length_m();
  options.render.resolution_m = options.resolution_m;
  options.occupancy_threshold = c.occupied_threshold();
  // 0: each sensor's full range (core's default); anything else, negative and NaN included,
  // goes to core to be checked.
  if (c.max_range_m() != 0.0) options.render.max_range_m = c.max_range_m();
  // 0: leave one hardware thread to ingest and queries. On 2 cores a second render thread
  // renders ~1.4x faster but lifts the p99 of small queries from ~1 ms to 2-4 ms while
  // sensors stream (BENCHMARKS.md, service_bench).
  options.render.threads = c.render_threads() != 0
                               ? c.render_threads()
                               : std::max(1u, std::thread::hardware_concurrency() - 1);
  // Core checks its options (one place); the message names the configuration's field.
  std::string why;
  if (!options.IsValid(&why)) return Status::Error(MapConfigError(why));
  return options;
}

StateThresholds ThresholdsFromConfig(const fusion::v1::MapConfig& c) {
  return {c.occupied_threshold(), c.free_threshold()};
}

Eigen::Isometry3d IsometryFromDds(const fusion_dds_Pose& pose) {
  const Eigen::Quaterniond q(pose.qw, pose.qx, pose.qy, pose.qz);
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = q.normalized().toRotationMatrix();
  T.translation() = Eigen::Vector3d(pose.tx, pose.ty, pose.tz);
  return T;
}

Cloud CloudFromDds(const fusion_dds_PointCloud& sample) {
  Cloud cloud;
  cloud.sensor_id = sample.sensor_id;
  cloud.sequence_number = sample.sequence_number;
  cloud.stamp_s = sample.stamp.sec + 1e-9 * sample.stamp.nanosec;
  cloud.T_world_published = IsometryFromDds(sample.T_world_sensor);
  cloud.width = sample.width;
  cloud.height = sample.height;
  cloud.xyz.assign(sample.xyz._buffer, sample.xyz._buffer + sample.xyz._length);
  cloud.beyond_range.assign(sample.beyond_range._buffer,
                            sample.beyond_range._buffer + sample.beyond_range._length);
  return cloud;
}

namespace {

std::string Text(const char* text) { return text != nullptr ? text : ""; }

ros2::Header Ros2FromDds(const std_msgs_msg_dds__Header_& header) {
  return {{header.stamp.sec, header.stamp.nanosec}, Text(header.frame_id)};
}

ros2::ByteView View(const dds_sequence_uint8& bytes) {
  return bytes._buffer != nullptr ? ros2::ByteView(bytes._buffer, bytes._length) : ros2::ByteView();
}

}  // namespace

ros2::PointCloud2 Ros2FromDds(const sensor_msgs_msg_dds__PointCloud2_& sample) {
  ros2::PointCloud2 msg;
  msg.header = Ros2FromDds(sample.header);
  msg.height = sample.height;
  msg.width = sample.width;
  const std::uint32_t fields = sample.fields._buffer != nullptr ? sample.fields._length : 0;
  msg.fields.reserve(fields);
  for (std::uint32_t i = 0; i < fields; ++i) {
    const auto& f = sample.fields._buffer[i];
    msg.fields.push_back({Text(f.name), f.offset, f.datatype, f.count});
  }
  msg.is_bigendian = sample.is_bigendian;
  msg.point_step = sample.point_step;
  msg.row_step = sample.row_step;
  msg.data = View(sample.data);
  msg.is_dense = sample.is_dense;
  return msg;
}

ros2::Image Ros2FromDds(const sensor_msgs_msg_dds__Image_& sample) {
  ros2::Image image;
  image.header = Ros2FromDds(sample.header);
  image.height = sample.height;
  image.width = sample.width;
  image.encoding = Text(sample.encoding);
  image.is_bigendian = sample.is_bigendian;
  image.step = sample.step;
  image.data = View(sample.data);
  return image;
}

ros2::CameraInfo Ros2FromDds(const sensor_msgs_msg_dds__CameraInfo_& sample) {
  ros2::CameraInfo info;
  info.header = Ros2FromDds(sample.header);
  info.height = sample.height;
  info.width = sample.width;
  info.distortion_model = Text(sample.distortion_model);
  if (sample.d._buffer != nullptr) {
    info.d.assign(sample.d._buffer, sample.d._buffer + sample.d._length);
  }
  std::copy(std::begin(sample.k), std::end(sample.k), info.k.begin());
  std::copy(std::begin(sample.r), std::end(sample.r), info.r.begin());
  std::copy(std::begin(sample.p), std::end(sample.p), info.p.begin());
  info.binning_x = sample.binning_x;
  info.binning_y = sample.binning_y;
  info.roi = {sample.roi.x_offset, sample.roi.y_offset, sample.roi.height, sample.roi.width,
              sample.roi.do_rectify};
  return info;
}

ros2::TFMessage Ros2FromDds(const tf2_msgs_msg_dds__TFMessage_& sample) {
  ros2::TFMessage msg;
  const std::uint32_t n = sample.transforms._buffer != nullptr ? sample.transforms._length : 0;
  msg.transforms.reserve(n);
  for (std::uint32_t i = 0; i < n; ++i) {
    const auto& t = sample.transforms._buffer[i];
    ros2::TransformStamped out;
    out.header = Ros2FromDds(t.header);
    out.child_frame_id = Text(t.child_frame_id);
    const auto& tr = t.transform.translation;
    const auto& q = t.transform.rotation;
    out.transform.translation = {tr.x, tr.y, tr.z};
    out.transform.rotation = {q.x, q.y, q.z, q.w};
    msg.transforms.push_back(std::move(out));
  }
  return msg;
}

Eigen::Isometry3d IsometryFromRos2(const ros2::Transform& transform) {
  const auto& q = transform.rotation;
  const auto& t = transform.translation;
  const double norm = std::sqrt(q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w);
  const Eigen::Quaterniond unit(q.w / norm, q.x / norm, q.y / norm, q.z / norm);
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = unit.toRotationMatrix();
  T.translation() = Eigen::Vector3d(t.x, t.y, t.z);
  return T;
}

std::string Ros2FrameId(const std::string& frame_id) {
  return !frame_id.empty() && frame_id.front() == '/' ? frame_id.substr(1) : frame_id;
}

Cloud CloudFromRos2(const std::string& sensor_id, std::uint64_t sequence_number, double stamp_s,
                    const Eigen::Isometry3d& T_map_frame, const Eigen::Isometry3d* T_sensor_frame,
                    std::uint32_t width, std::uint32_t height, std::vector<float> xyz) {
  Cloud cloud;
  cloud.sensor_id = sensor_id;
  cloud.sequence_number = sequence_number;
  cloud.stamp_s = stamp_s;
  cloud.T_world_published = T_map_frame;
  cloud.width = width;
  cloud.height = height;
  if (T_sensor_frame != nullptr) {
    const Eigen::Matrix3f R = T_sensor_frame->linear().cast<float>();
    const Eigen::Vector3f t = T_sensor_frame->translation().cast<float>();
    for (std::size_t i = 0; i + 2 < xyz.size(); i += 3) {
      Eigen::Map<Eigen::Vector3f> p(&xyz[i]);
      p = R * p + t;  // NaN (no return) stays NaN
    }
  }
  cloud.xyz = std::move(xyz);
  return cloud;
}

Eigen::Vector3d FromProto(const fusion::v1::Point& p) { return {p.x(), p.y(), p.z()}; }

void ToProto(const Eigen::Vector3d& v, fusion::v1::Point* p) {
  p->set_x(v.x());
  p->set_y(v.y());
  p->set_z(v.z());
}

fusion::v1::VoxelState StateOf(double probability, const StateThresholds& t) {
  if (probability >= t.occupied) return fusion::v1::VOXEL_STATE_OCCUPIED;
  if (probability < t.free) return fusion::v1::VOXEL_STATE_FREE;
  return fusion::v1::VOXEL_STATE_UNKNOWN;
}

void VoxelToProto(const octomap::OcTree& tree, const octomap::OcTreeKey& key, unsigned depth,
                  const octomap::OcTreeNode* node, const StateThresholds& t,
                  fusion::v1::Voxel* voxel) {
  const octomap::point3d c = tree.keyToCoord(key, depth);
  ToProto(Eigen::Vector3d(c.x(), c.y(), c.z()), voxel->mutable_center());
  voxel->set_size_m(tree.getNodeSize(depth));
  const double p = node != nullptr ? node->getOccupancy() : 0.5;
  voxel->set_probability(p);
  voxel->set_state(node != nullptr ? StateOf(p, t) : fusion::v1::VOXEL_STATE_UNKNOWN);
}

void PlaneToProto(const Plane& plane, fusion::v1::Plane* out) {
  out->set_phi_deg(plane.phi_rad / kDegToRad);
  out->set_theta_deg(plane.theta_rad / kDegToRad);
  out->set_d_m(plane.distance_m);
  ToProto(plane.normal, out->mutable_normal());
  out->set_votes(plane.votes);
  out->set_support_voxels(plane.support_voxels);
  out->set_rms_m(plane.rms_m);
  if (!plane.extent.isEmpty()) {
    ToProto(plane.extent.min(), out->mutable_extent_min());
    ToProto(plane.extent.max(), out->mutable_extent_max());
  }
}

HoughOptions HoughOptionsFromProto(const fusion::v1::FindPlanesRequest& request,
                                   double resolution_m) {
  HoughOptions options;
  if (request.has_region_min() || request.has_region_max()) {
    options.region =
        Eigen::AlignedBox3d(FromProto(request.region_min()), FromProto(request.region_max()));
  }
  if (request.max_planes() > 0) options.max_planes = request.max_planes();
  if (request.min_probability() > 0.0) options.min_probability = request.min_probability();
  if (request.angle_step_deg() > 0.0) {
    options.phi_bin_rad = options.theta_bin_rad = request.angle_step_deg() * kDegToRad;
  }
  options.d_bin_m = request.distance_step_m() > 0.0 ? request.distance_step_m() : resolution_m;
  if (request.min_support_voxels() > 0) options.min_support_voxels = request.min_support_voxels();
  return options;
}

}  // namespace fusion::service
