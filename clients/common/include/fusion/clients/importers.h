// Importers of recorded range data into RecordedCloud messages: TUM RGB-D depth sequences,
// PCD files (ascii, binary, binary_compressed), OctoMap scan graphs and plain x y z scans.
// Points always end up in the sensor frame (metres, NaN = no return) with the sensor's pose
// in the world frame in t_world_sensor.
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "fusion/core/status.h"
#include "fusion/v1/recording.pb.h"

namespace fusion::clients {

// Receives the imported clouds one at a time (so long sequences need not fit in memory).
using CloudSink = std::function<Status(fusion::v1::RecordedCloud&& cloud)>;

// TUM RGB-D: depth/<stamp>.png (16-bit, value / depth_scale = depth along the optical axis in
// metres, 0 = missing) listed with their poses in groundtruth.txt ("depth/x.png tx ty tz qx qy
// qz qw" = pose of the optical frame in the world).
struct TumOptions {
  std::string directory;  // holds groundtruth.txt and depth/
  std::string groundtruth = "groundtruth.txt";
  std::uint32_t stride = 1;  // keep every stride-th pixel in both directions
  double fx_px = 520.9, fy_px = 521.0, cx_px = 325.1, cy_px = 249.7;  // TUM fr2 intrinsics
  double depth_scale = 5000.0;                                        // PNG units per metre
  std::string sensor_id = "tum";
  std::uint64_t max_frames = 0;  // 0 = all
};
// A depth image's size in pixels.
struct ImageSize {
  std::uint32_t width_px = 0, height_px = 0;
};
// *image_size (if given) receives the size of the depth images (of the last one read).
Status ImportTum(const TumOptions& options, const CloudSink& sink, ImageSize* image_size = nullptr);

// A 16-bit grayscale PNG as row-major values (width * height).
Status ReadPng16(const std::string& path, std::uint32_t* width, std::uint32_t* height,
                 std::vector<std::uint16_t>* values);

// PCD v0.5-0.7: DATA ascii, binary or binary_compressed (LZF, column-wise); fields x y z of
// type F (float or double), other fields ignored; organized or not. The points are stored
// relative to VIEWPOINT (tx ty tz qw qx qy qz), which becomes t_world_sensor. Sets geometry
// and pose only (not the sensor id, stamp or sequence number). With apply_viewpoint false the
// VIEWPOINT is ignored: points stay as stored and the pose is the identity (some files carry
// a meaningless VIEWPOINT, e.g. PCL's table_scene_mug_stereo_textured.pcd says "0 0 0 0 1 0 0",
// a half turn about x that would put the whole scene behind the camera).
Status ReadPcd(const std::string& path, fusion::v1::RecordedCloud* cloud,
               bool apply_viewpoint = true);

// Fraction of the finite points with z < 0 in the sensor frame (behind a camera), 0 if none.
double FractionBehindSensor(const fusion::v1::RecordedCloud& cloud);

// Plain text scans: one "x y z" per line (metres, scanner frame), optionally bzip2-compressed
// (name ending in .bz2, decompressed through `bzip2 -dc`). Lines "NODE x y z roll pitch yaw"
// (OctoMap's log format) start a new cloud taken at that pose; points before any NODE line
// belong to a cloud at `pose`. '#' starts a comment. One cloud per node, unorganized. The
// points and poses stay in the file's frame: ToOpticalFrame below turns body-frame scans (and
// scan graphs) into what fusiond reads.
Status ReadXyzScan(const std::string& path, const fusion::v1::RecordedPose& pose,
                   std::vector<fusion::v1::RecordedCloud>* clouds);

// OctoMap's binary scan graph (.graph, octomap::ScanGraph::writeBinary): one cloud per node,
// its points in the node's frame, the node pose as t_world_sensor.
Status ReadScanGraph(const std::string& path, std::vector<fusion::v1::RecordedCloud>* clouds);

// The frame a file's points (and the pose given with them) are in. fusiond reads points in
// the sensor's optical frame (x right, y down, z forward); scanners and robots use the body
// frame of REP-103 (x forward, y left, z up).
enum class PointFrame { kOptical, kBody };
// "optical" or "body"; errors name the flag.
Status ParsePointFrame(const std::string& flag, const std::string& text, PointFrame* frame);
// Re-expresses a cloud whose points and t_world_sensor are in `frame` in the optical frame:
// p_optical = R_optical_body p_body (x_o = -y_b, y_o = -z_b, z_o = x_b) and T_world_optical =
// T_world_body T_body_optical, so every world point stays where it was. kOptical: unchanged.
void ToOpticalFrame(PointFrame frame, fusion::v1::RecordedCloud* cloud);

// Sets the identity of an imported cloud: sensor id, sequence number, stamp (seconds since the
// epoch) and the receive time replay paces by (the same instant).
void SetIdentity(const std::string& sensor_id, std::uint64_t sequence_number, double stamp_s,
                 const std::string& origin, fusion::v1::RecordedCloud* cloud);

// Point i of a cloud as float x y z (host order).
void GetPoint(const fusion::v1::RecordedCloud& cloud, std::size_t i, float xyz[3]);
// Appends a point (host floats) to xyz_f32le.
void AppendPoint(float x, float y, float z, fusion::v1::RecordedCloud* cloud);

}  // namespace fusion::clients
