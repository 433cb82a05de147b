// Synthetic scenes for the range-sensor simulator: bounded rectangles (planes
// such as the paper's textured board or a floor) and oriented boxes, in the
// world frame, metres.
//
// Scene file format (docs/mapping.md): one object per line, '#' starts a
// comment.
//   rect NAME cx cy cz  ux uy uz  vx vy vz  size_u size_v  [untextured]
//   box  NAME cx cy cz  size_x size_y size_z  [roll_deg pitch_deg yaw_deg]
//   [untextured]
// A rect spans size_u along u and size_v along v around its centre (v is made
// orthogonal to u); a box is rotated by R = Rz(yaw) Ry(pitch) Rx(roll).
// "untextured" surfaces give no returns to sensors that need texture (stereo).
// Dynamic scenes: after the numbers, any of
//   from T            the object appears at scene time T (seconds)
//   until T           and is gone from T on
//   path T X Y Z ...  its centre at those times (ascending), linear in between,
//                     held before the first and after the last
// e.g. "box person 2 1 0.45  0.4 0.4 1.7  path 0 2 1 0.45  2 2 -1 0.45" walks
// 2 m across the view in 2 s.
#pragma once

#include <Eigen/Geometry>
#include <cmath>
#include <limits>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace fusion::sim {

// When an object exists and where its centre is (scene time, seconds).
struct Motion {
  double from_s = -std::numeric_limits<double>::infinity();
  double until_s = std::numeric_limits<double>::infinity();
  std::vector<std::pair<double, Eigen::Vector3d>> path;  // (t_s, centre_m), t ascending

  [[nodiscard]] bool IsStatic() const { return path.empty() && !std::isfinite(from_s) &&
                                               !std::isfinite(until_s); }
  [[nodiscard]] bool PresentAt(double t_s) const { return t_s >= from_s && t_s < until_s; }
  // The centre at t_s, or `fixed` without a path.
  [[nodiscard]] Eigen::Vector3d CentreAt(double t_s, const Eigen::Vector3d& fixed) const;
};

struct Rectangle {
  std::string name;
  Eigen::Vector3d center_m = Eigen::Vector3d::Zero();
  Eigen::Vector3d axis_u = Eigen::Vector3d::UnitX();  // unit
  Eigen::Vector3d axis_v = Eigen::Vector3d::UnitY();  // unit, orthogonal to axis_u
  double half_u_m = 0.5;
  double half_v_m = 0.5;
  bool textured = true;
  Motion motion;
  [[nodiscard]] Eigen::Vector3d Normal() const { return axis_u.cross(axis_v).normalized(); }
};

struct Box {
  std::string name;
  Eigen::Isometry3d T_world_box = Eigen::Isometry3d::Identity();
  Eigen::Vector3d half_extents_m = Eigen::Vector3d::Constant(0.5);
  bool textured = true;
  Motion motion;
};

struct RayHit {
  double range_m = 0.0;
  bool textured = true;
  int object = -1;  // rectangles first, then boxes
};

class Scene {
 public:
  void AddRectangle(const Rectangle& rectangle);
  void AddBox(const Box& box);
  [[nodiscard]] const std::vector<Rectangle>& rectangles() const { return rectangles_; }
  [[nodiscard]] const std::vector<Box>& boxes() const { return boxes_; }
  [[nodiscard]] bool empty() const { return rectangles_.empty() && boxes_.empty(); }
  // Whether some object appears, disappears or moves.
  [[nodiscard]] bool IsDynamic() const;
  // The scene as it is at scene time t_s: the objects present then, at their centres then
  // (static objects as they are). Object indices (RayHit::object) refer to this scene.
  [[nodiscard]] Scene At(double t_s) const;

  // First surface along origin + t * direction (direction unit, world frame), t
  // in (0, max_range_m]; std::nullopt if none.
  [[nodiscard]] std::optional<RayHit> Raycast(const Eigen::Vector3d& origin_m,
                                              const Eigen::Vector3d& direction,
                                              double max_range_m) const;
  // Distance from a world point to the nearest surface (box surfaces, not
  // volumes).
  [[nodiscard]] double DistanceToSurface(const Eigen::Vector3d& p_m) const;
  // True if some surface passes through the axis-aligned box [min_m, max_m].
  [[nodiscard]] bool SurfaceIntersects(const Eigen::AlignedBox3d& box_m) const;

 private:
  std::vector<Rectangle> rectangles_;
  std::vector<Box> boxes_;
};

// Parses the scene file format above. On error returns std::nullopt and sets
// *error
// ("line N: ...") if error is not null.
[[nodiscard]] std::optional<Scene> ParseScene(const std::string& text,
                                              std::string* error = nullptr);
[[nodiscard]] std::optional<Scene> LoadSceneFile(const std::string& path,
                                                 std::string* error = nullptr);

// The paper's Fig. 5 experiment, world frame x forward, y left, z up, the
// SR-3000 at the origin looking along +x:
struct PaperSetup {
  static constexpr double kBoardDistanceM = 1.75;  // board plane x = 1.75
  static constexpr double kBoardWidthM = 1.2;      // along y, centred on y = 0
  static constexpr double kBoardHeightM = 1.0;     // z from kBoardBottomZM
  static constexpr double kBoardBottomZM = -0.30;
  static constexpr double kFloorZM = -0.41;  // sensors 0.41 m (SR) / 0.33 m (stereo) above it
  // Stereo camera relative to the SR-3000: 25 mm to the left, 80 mm down (paper
  // Sec. V).
  static constexpr double kStereoLeftM = 0.025;
  static constexpr double kStereoDownM = 0.080;
};
// Textured board plus an untextured floor (4 m x 4 m from x = 0): as in the
// paper, only the time-of-flight camera sees the floor when the simulator
// requires texture for stereo.
[[nodiscard]] Scene PaperBoardScene();

// Pose of a sensor (optical frame: x right, y down, z forward) at position_m
// looking along world +x with world +z up; yaw/pitch rotate the view (pitch > 0
// looks down).
[[nodiscard]] Eigen::Isometry3d ForwardLookingPose(const Eigen::Vector3d& position_m,
                                                   double yaw_rad = 0.0, double pitch_rad = 0.0);

}  // namespace fusion::sim
