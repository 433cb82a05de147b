// The sensors { ... } blocks of --print-sensor: what was estimated, as a fusion.v1.SensorConfig
// in protobuf text format.
#include "fusion/clients/sensor_block.h"

#include <google/protobuf/text_format.h>

#include <cmath>
#include <cstdio>

namespace fusion::clients {

namespace {

// A fit beyond this (pixels rms) is not a pinhole camera's: the angular form describes it.
constexpr double kMaxPinholeRmsPx = 1.0;

// Rounded to 1 / per_unit (dividing by an integer, so 0.3 prints as 0.3, not 0.30000000000000004).
double RoundTo(double value, double per_unit) { return std::round(value * per_unit) / per_unit; }

std::string Format(const char* format, double a, double b = 0, double c = 0, double d = 0) {
  char line[256];
  std::snprintf(line, sizeof line, format, a, b, c, d);
  return line;
}

}  // namespace

void RangeSeen::Add(const fusion::v1::RecordedCloud& cloud) {
  const std::size_t n = cloud.xyz_f32le().size() / 12;
  for (std::size_t i = 0; i < n; ++i) {
    float p[3];
    GetPoint(cloud, i, p);
    const double r_m = std::sqrt(double{p[0]} * p[0] + double{p[1]} * p[1] + double{p[2]} * p[2]);
    if (!std::isfinite(r_m) || !(r_m > 0)) continue;
    min_m = std::min(min_m, r_m);
    max_m = std::max(max_m, r_m);
  }
}

void ImportedGeometry::Add(const fusion::v1::RecordedCloud& cloud) {
  ranges_.Add(cloud);
  angular_.Add(cloud);
  if (!pinhole_.Add(cloud)) all_organized_ = false;
}

Status ImportedGeometry::Describe(const std::string& sensor_id, const std::string& angular_preset,
                                  fusion::v1::SensorConfig* sensor, std::string* notes) const {
  if (ranges_.empty()) return Status::Error("no returns to describe the sensor by");
  notes->clear();
  if (all_organized_) {
    PinholeFit fit;
    const Status s = pinhole_.Fit(&fit);
    if (s.ok() && fit.rms_px <= kMaxPinholeRmsPx) {
      *sensor = PinholeSensorConfig(sensor_id, fit, ranges_);
      *notes += Format("pinhole camera fitted to %.0f returns: fx %.2f fy %.2f px, rms %.3f px\n",
                       static_cast<double>(fit.points), fit.fx_px, fit.fy_px, fit.rms_px);
      *notes += "no preset: add the sensor's noise model (q_mu, q_sigma) or a preset\n";
      return Status::Ok();
    }
    *notes += s.ok() ? Format("organized, but not a pinhole camera (rms %.1f px): angular form\n",
                              fit.rms_px)
                     : s.message() + ": angular form\n";
  }
  AngularGrid grid;
  if (Status s = angular_.Fit(&grid); !s.ok()) return s;
  *sensor = AngularSensorConfig(sensor_id, angular_preset, grid, ranges_);
  *notes += Format(
      "returns spaced about %.3f deg across, %.3f deg down: %.0f beams for %.0f "
      "returns a scan\n",
      grid.azimuth_step_deg, grid.elevation_step_deg, static_cast<double>(grid.cols) * grid.rows,
      static_cast<double>(grid.returns_per_scan));
  if (angular_preset.empty()) {
    *notes += "no preset: add the sensor's noise model (q_mu, q_sigma) or a preset\n";
  }
  return Status::Ok();
}

fusion::v1::SensorConfig TumSensorConfig(const TumOptions& options, const ImageSize& image) {
  fusion::v1::SensorConfig sensor;
  sensor.set_id(options.sensor_id);
  sensor.set_preset("kinect_v1");
  auto* pinhole = sensor.mutable_pinhole();
  pinhole->set_fx(options.fx_px);
  pinhole->set_fy(options.fy_px);
  pinhole->set_cx(options.cx_px);
  pinhole->set_cy(options.cy_px);
  pinhole->set_width(image.width_px);
  pinhole->set_height(image.height_px);
  pinhole->set_stride(options.stride);
  return sensor;
}

fusion::v1::SensorConfig PinholeSensorConfig(const std::string& sensor_id, const PinholeFit& fit,
                                             const RangeSeen& ranges) {
  fusion::v1::SensorConfig sensor;
  sensor.set_id(sensor_id);
  SetRangesRoundedOut(ranges, &sensor);
  auto* pinhole = sensor.mutable_pinhole();
  pinhole->set_fx(RoundTo(fit.fx_px, 100));
  pinhole->set_fy(RoundTo(fit.fy_px, 100));
  pinhole->set_cx(RoundTo(fit.cx_px, 100));
  pinhole->set_cy(RoundTo(fit.cy_px, 100));
  pinhole->set_width(fit.width_px);
  pinhole->set_height(fit.height_px);
  pinhole->set_stride(1);
  return sensor;
}

fusion::v1::SensorConfig AngularSensorConfig(const std::string& sensor_id,
                                             const std::string& preset, const AngularGrid& grid,
                                             const RangeSeen& ranges) {
  fusion::v1::SensorConfig sensor;
  sensor.set_id(sensor_id);
  sensor.set_preset(preset);
  SetRangesRoundedOut(ranges, &sensor);
  sensor.set_azimuth_min_deg(grid.azimuth_min_deg);
  sensor.set_azimuth_max_deg(grid.azimuth_max_deg);
  sensor.set_elevation_min_deg(grid.elevation_min_deg);
  sensor.set_elevation_max_deg(grid.elevation_max_deg);
  sensor.set_cols(grid.cols);
  sensor.set_rows(grid.rows);
  return sensor;
}

void SetRangesRoundedOut(const RangeSeen& ranges, fusion::v1::SensorConfig* sensor) {
  const double per_m = ranges.min_m >= 0.1 ? 10 : 100;
  sensor->set_r_min_m(std::floor(ranges.min_m * per_m) / per_m);
  sensor->set_r_max_m(std::ceil(ranges.max_m * 10) / 10);
}

std::string SensorBlockText(const fusion::v1::SensorConfig& sensor) {
  fusion::v1::ServiceConfig config;
  *config.add_sensors() = sensor;
  std::string text;
  google::protobuf::TextFormat::PrintToString(config, &text);
  return text;
}

}  // namespace fusion::clients
