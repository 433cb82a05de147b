#include "fusion/core/sensor_periods.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "fusion/core/local_grid.h"

namespace fusion {

const char* MapStatusName(MapStatus status) {
  switch (status) {
    case MapStatus::kOk:
      return "ok";
    case MapStatus::kUnknownSensor:
      return "unknown sensor";
    case MapStatus::kDuplicateSensor:
      return "duplicate sensor";
    case MapStatus::kInvalidPose:
      return "invalid pose";
    case MapStatus::kInvalidArgument:
      return "invalid argument";
    case MapStatus::kOutsideMap:
      return "outside the map";
  }
  return "unknown status";
}

bool ValidPose(const Eigen::Isometry3d& T) {
  if (!T.matrix().allFinite()) return false;
  const Eigen::Matrix3d R = T.linear();
  if ((R.transpose() * R - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff() > 1e-3) return false;
  return R.determinant() > 0.0;
}

SensorPeriods::SensorPeriods(const SensorSpec& spec, const BeamGridOptions& grid_options,
                             double pose_tolerance_m, double pose_tolerance_rad,
                             double map_resolution_m)
    : spec_(spec),
      grid_spec_(WidenedFieldOfView(
          spec,
          pose_tolerance_rad + std::atan(pose_tolerance_m / std::max(kMarginRangeM, spec.r_min_m)),
          &margin_)),
      grid_options_(grid_options),
      pose_tolerance_m_(pose_tolerance_m),
      pose_tolerance_rad_(pose_tolerance_rad),
      map_resolution_m_(map_resolution_m) {
  open_ = NewPeriod();
}

std::unique_ptr<Period> SensorPeriods::NewPeriod() {
  std::unique_ptr<Period> p;
  if (spare_) {
    p = std::move(spare_);
    p->grid->Reset();  // here, not in Recycle: on the integrating thread, not the renderer's
    p->frames = p->merged_frames = 0;
  } else {
    p = std::make_unique<Period>();
    // Every grid of the sensor shares the first one's forward-model tables.
    p->grid =
        open_ ? open_->grid->EmptyCopy() : std::make_unique<BeamGrid>(grid_spec_, grid_options_);
  }
  p->sequence = ++sequence_;
  return p;
}

bool SensorPeriods::Moved(const Eigen::Isometry3d& T_world_sensor) const {
  const double translation_m =
      (T_world_sensor.translation() - open_->T_world_sensor.translation()).norm();
  const Eigen::AngleAxisd delta(open_->T_world_sensor.linear().transpose() *
                                T_world_sensor.linear());
  return translation_m > pose_tolerance_m_ || std::abs(delta.angle()) > pose_tolerance_rad_;
}

bool SensorPeriods::WouldSeal(const Eigen::Isometry3d& T_world_sensor) const {
  if (!ValidPose(T_world_sensor) || open_->frames == 0) return false;
  if (map_resolution_m_ > 0.0 && !InsideMap(T_world_sensor.translation(), map_resolution_m_)) {
    return false;
  }
  return Moved(T_world_sensor);
}

const float* SensorPeriods::InsideMapOnly(const Eigen::Isometry3d& T_world_frame,
                                          const float* points, std::size_t point_count,
                                          const std::vector<std::uint8_t>& beyond_range,
                                          std::size_t* outside) {
  *outside = 0;
  if (!(map_resolution_m_ > 0.0)) return points;
  // No point can be outside if the farthest one, from anywhere near the origin, is not.
  double farthest = 0.0;
  for (std::size_t k = 0; k < 3 * point_count; ++k) {
    if (std::isfinite(points[k])) farthest = std::max(farthest, std::abs(double{points[k]}));
  }
  const double margin = T_world_frame.translation().cwiseAbs().maxCoeff() +
                        std::sqrt(3.0) * farthest + map_resolution_m_;
  if (margin < MapHalfExtentM(map_resolution_m_)) return points;
  inside_.assign(points, points + 3 * point_count);
  constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();
  for (std::size_t k = 0; k < point_count; ++k) {
    float* p = &inside_[3 * k];
    const Eigen::Vector3d q(p[0], p[1], p[2]);
    if (!q.allFinite() || q.isZero()) continue;  // the beam grid's to count
    // A beyond-range reading only gives its beam's direction: its free space is rendered up
    // to the map's edge, never past it.
    if (!beyond_range.empty() && beyond_range[k] != 0) continue;
    if (InsideMap(T_world_frame * q, map_resolution_m_)) continue;
    p[0] = p[1] = p[2] = kNaN;
    ++*outside;
  }
  return inside_.data();
}

const float* SensorPeriods::IntoOpenFrame(const Eigen::Isometry3d& T_world_cloud,
                                          const float* points, std::size_t point_count) {
  // NaN stays NaN (no return), and so does every count; a "missing" (0, 0, 0) point stays so.
  const Eigen::Isometry3d T_open_cloud = open_->T_world_sensor.inverse() * T_world_cloud;
  moved_.resize(3 * point_count);
  for (std::size_t k = 0; k < point_count; ++k) {
    const Eigen::Vector3d p(points[3 * k], points[3 * k + 1], points[3 * k + 2]);
    const Eigen::Vector3d q = T_open_cloud * p;
    const bool zero = p.x() == 0.0 && p.y() == 0.0 && p.z() == 0.0;
    for (int a = 0; a < 3; ++a) moved_[3 * k + a] = zero ? 0.0f : static_cast<float>(q[a]);
  }
  return moved_.data();
}

MapStatus SensorPeriods::Integrate(const Eigen::Isometry3d& T_world_sensor,
                                   const float* points_xyz, std::size_t point_count,
                                   const std::vector<std::uint8_t>& beyond_range, bool may_seal,
                                   PeriodIntegration* result, std::unique_ptr<Period>* sealed) {
  if (!ValidPose(T_world_sensor)) return MapStatus::kInvalidPose;
  if (points_xyz == nullptr && point_count != 0) return MapStatus::kInvalidArgument;
  if (!beyond_range.empty() && beyond_range.size() != point_count) {
    return MapStatus::kInvalidArgument;
  }
  if (map_resolution_m_ > 0.0 && !InsideMap(T_world_sensor.translation(), map_resolution_m_)) {
    return MapStatus::kOutsideMap;
  }
  PeriodIntegration out;
  if (open_->frames > 0 && Moved(T_world_sensor)) {
    if (may_seal) {
      std::unique_ptr<Period> next = NewPeriod();
      *sealed = std::move(open_);
      open_ = std::move(next);
    } else {
      out.merged = true;
      ++open_->merged_frames;
    }
  }
  if (open_->frames == 0) open_->T_world_sensor = T_world_sensor;
  // A cloud taken anywhere but at the period's pose (within the tolerance, or merged) goes in
  // with its points where they were measured: only its rays' origin is approximated.
  const float* points = T_world_sensor.matrix() == open_->T_world_sensor.matrix()
                            ? points_xyz
                            : IntoOpenFrame(T_world_sensor, points_xyz, point_count);
  std::size_t outside = 0;
  points = InsideMapOnly(open_->T_world_sensor, points, point_count, beyond_range, &outside);
  out.stats = open_->grid->Integrate(points, point_count, beyond_range);
  out.stats.missing -= outside;  // made NaN above: counted as outside the map instead
  out.stats.rejected_outside_map = outside;
  ++open_->frames;
  if (result != nullptr) *result = out;
  return MapStatus::kOk;
}

std::unique_ptr<Period> SensorPeriods::Seal() {
  if (open_->frames == 0) return nullptr;
  std::unique_ptr<Period> next = NewPeriod();
  std::unique_ptr<Period> sealed = std::move(open_);
  open_ = std::move(next);
  return sealed;
}

void SensorPeriods::Recycle(std::unique_ptr<Period> period) {
  if (!period || spare_) return;  // one spare is enough: the rest go
  spare_ = std::move(period);  // reset when it is taken (NewPeriod)
}

void SensorPeriods::Reset() {
  open_->grid->Reset();
  open_->frames = open_->merged_frames = 0;
}

std::size_t SensorPeriods::MemoryBytes() const {
  return open_->grid->MemoryBytes() + (spare_ ? spare_->grid->MemoryBytes() : 0);
}

}  // namespace fusion
