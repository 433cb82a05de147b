// fusion-import --print-sensor: the `sensors { ... }` block of fusiond's configuration (a
// fusion.v1.SensorConfig in protobuf text format) that describes the geometry of the imported
// clouds, estimated from their points in the optical frame (x right, y down, z forward, metres).
#pragma once

#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#include "fusion/clients/importers.h"
#include "fusion/core/status.h"
#include "fusion/v1/config.pb.h"
#include "fusion/v1/recording.pb.h"

namespace fusion::clients {

// Shortest and longest range (Euclidean norm, metres) of the finite, non-zero returns.
struct RangeSeen {
  double min_m = std::numeric_limits<double>::infinity();
  double max_m = 0;
  void Add(const fusion::v1::RecordedCloud& cloud);
  [[nodiscard]] bool empty() const { return !(max_m > 0); }
};

// A camera's intrinsics fitted to organized clouds (pixel (u, v) = column u, row v).
struct PinholeFit {
  double fx_px = 0, fy_px = 0, cx_px = 0, cy_px = 0;
  std::uint32_t width_px = 0, height_px = 0;
  std::uint64_t points = 0;  // returns fitted
  double rms_px = 0;         // residual over both axes
};

// Least squares of u = fx x/z + cx over the columns and v = fy y/z + cy over the rows of
// organized clouds, from the finite points with z > 0.
class PinholeEstimator {
 public:
  // False (and the cloud unused) when it is unorganized or not the size of the first one.
  bool Add(const fusion::v1::RecordedCloud& cloud);
  [[nodiscard]] Status Fit(PinholeFit* fit) const;

 private:
  // Sums of the normal equations of p = f a + c.
  struct Line {
    double n = 0, a = 0, aa = 0, p = 0, ap = 0, pp = 0;
    void Add(double a_value, double p_value);
  };
  Line u_, v_;
  std::uint32_t width_px_ = 0, height_px_ = 0;
};

// Angular extents of the returns and a beam grid of about their spacing (degrees).
struct AngularGrid {
  // The extents of every return, widened by one beam each side and rounded out to 0.1 deg.
  double azimuth_min_deg = 0, azimuth_max_deg = 0;
  double elevation_min_deg = 0, elevation_max_deg = 0;
  double azimuth_step_deg = 0, elevation_step_deg = 0;  // the estimated spacing of returns
  std::uint32_t cols = 0, rows = 0;
  std::uint64_t returns_per_scan = 0;  // of the densest cloud, which gave the spacing
};

// Directions of returns: azimuth = atan2(x, z) (to the right), elevation = atan2(-y,
// hypot(x, z)) (up). The spacing comes from the cloud with the most returns: the area its
// returns cover (cells of 4 mean spacings that hold one) over their number gives the area per
// return, and the nearest neighbours of a sample, across and down, its aspect ratio. So the
// grid has about one beam per return where there are returns (never more than 4 per return
// overall), not one per the closest pair of returns (scan lines that crowd together).
class AngularEstimator {
 public:
  void Add(const fusion::v1::RecordedCloud& cloud);
  [[nodiscard]] Status Fit(AngularGrid* grid) const;

 private:
  struct Direction {
    float azimuth_deg, elevation_deg;
  };
  double azimuth_min_deg_ = 180, azimuth_max_deg_ = -180;
  double elevation_min_deg_ = 90, elevation_max_deg_ = -90;
  std::vector<Direction> densest_;  // the directions of the cloud with the most returns
};

// Everything --print-sensor needs, fed every imported cloud (optical frame).
class ImportedGeometry {
 public:
  void Add(const fusion::v1::RecordedCloud& cloud);
  // The pinhole form if every cloud was organized, of one size, and fits a pinhole camera
  // (rms under 1 px), else the angular form with `angular_preset` (may be empty). *notes:
  // lines for people (what was fitted, what the block lacks).
  [[nodiscard]] Status Describe(const std::string& sensor_id, const std::string& angular_preset,
                                fusion::v1::SensorConfig* sensor, std::string* notes) const;

 private:
  RangeSeen ranges_;
  PinholeEstimator pinhole_;
  AngularEstimator angular_;
  bool all_organized_ = true;
};

// TUM: preset "kinect_v1" with the import's intrinsics, image size and stride.
fusion::v1::SensorConfig TumSensorConfig(const TumOptions& options, const ImageSize& image);
// A camera without preset: pinhole (stride 1) and r_min_m / r_max_m.
fusion::v1::SensorConfig PinholeSensorConfig(const std::string& sensor_id, const PinholeFit& fit,
                                             const RangeSeen& ranges);
// The angular form: azimuth / elevation limits, cols, rows, r_min_m / r_max_m, the preset.
fusion::v1::SensorConfig AngularSensorConfig(const std::string& sensor_id,
                                             const std::string& preset, const AngularGrid& grid,
                                             const RangeSeen& ranges);
// r_min_m rounded down, r_max_m up, to 0.1 m (to 0.01 m below 0.1 m).
void SetRangesRoundedOut(const RangeSeen& ranges, fusion::v1::SensorConfig* sensor);

// "sensors {\n  id: ...\n}\n": the block as it goes into fusiond's configuration file.
std::string SensorBlockText(const fusion::v1::SensorConfig& sensor);

}  // namespace fusion::clients
