#include "fusion/sim/scene.h"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <limits>
#include <sstream>

namespace fusion::sim {
namespace {

constexpr double kDegToRad = 0.017453292519943295;

// Projection half-width of an axis-aligned box (half extents h) on axis a.
double AabbRadius(const Eigen::Vector3d& h, const Eigen::Vector3d& a) {
  return h.x() * std::abs(a.x()) + h.y() * std::abs(a.y()) + h.z() * std::abs(a.z());
}

bool SeparatedOn(const Eigen::Vector3d& axis, double center_gap, double r1, double r2) {
  if (axis.squaredNorm() < 1e-18) return false;
  return std::abs(center_gap) > r1 + r2;
}

// The rectangle's extent is taken inset_m smaller on each side (SurfaceIntersects).
bool RectangleIntersectsAabb(const Rectangle& r, const Eigen::AlignedBox3d& box, double inset_m) {
  const Eigen::Vector3d c = box.center();
  const Eigen::Vector3d h = box.sizes() / 2.0;
  const Eigen::Vector3d t = r.center_m - c;
  auto rect_radius = [&](const Eigen::Vector3d& a) {
    return (r.half_u_m - inset_m) * std::abs(r.axis_u.dot(a)) +
           (r.half_v_m - inset_m) * std::abs(r.axis_v.dot(a));
  };
  std::vector<Eigen::Vector3d> axes = {Eigen::Vector3d::UnitX(), Eigen::Vector3d::UnitY(),
                                       Eigen::Vector3d::UnitZ(), r.Normal()};
  for (int i = 0; i < 3; ++i) {
    const Eigen::Vector3d e = Eigen::Vector3d::Unit(i);
    axes.push_back(e.cross(r.axis_u));
    axes.push_back(e.cross(r.axis_v));
  }
  for (const auto& a : axes) {
    if (SeparatedOn(a, t.dot(a), rect_radius(a), AabbRadius(h, a))) return false;
  }
  return true;
}

// The box's half extents are taken inset_m smaller (SurfaceIntersects).
bool ObbOverlapsAabb(const Box& b, const Eigen::AlignedBox3d& box, double inset_m) {
  const Eigen::Vector3d c = box.center();
  const Eigen::Vector3d h = box.sizes() / 2.0;
  const Eigen::Matrix3d R = b.T_world_box.linear();
  const Eigen::Vector3d t = b.T_world_box.translation() - c;
  auto obb_radius = [&](const Eigen::Vector3d& a) {
    double s = 0.0;
    for (int i = 0; i < 3; ++i) s += (b.half_extents_m[i] - inset_m) * std::abs(R.col(i).dot(a));
    return s;
  };
  std::vector<Eigen::Vector3d> axes;
  for (int i = 0; i < 3; ++i) {
    axes.push_back(Eigen::Vector3d::Unit(i));
    axes.push_back(R.col(i));
    for (int j = 0; j < 3; ++j) axes.push_back(Eigen::Vector3d::Unit(i).cross(R.col(j)));
  }
  for (const auto& a : axes) {
    if (SeparatedOn(a, t.dot(a), obb_radius(a), AabbRadius(h, a))) return false;
  }
  return true;
}

bool InsideBox(const Box& b, const Eigen::Vector3d& p, double inset_m) {
  const Eigen::Vector3d q = b.T_world_box.inverse() * p;
  return (q.cwiseAbs().array() - (b.half_extents_m.array() - inset_m)).maxCoeff() <= 0.0;
}

std::optional<double> RayBox(const Box& b, const Eigen::Vector3d& origin,
                             const Eigen::Vector3d& dir, double max_range) {
  const Eigen::Isometry3d T_box_world = b.T_world_box.inverse();
  const Eigen::Vector3d o = T_box_world * origin;
  const Eigen::Vector3d d = T_box_world.linear() * dir;
  double t_near = -std::numeric_limits<double>::infinity();
  double t_far = std::numeric_limits<double>::infinity();
  for (int i = 0; i < 3; ++i) {
    const double h = b.half_extents_m[i];
    if (std::abs(d[i]) < 1e-15) {
      if (std::abs(o[i]) > h) return std::nullopt;
      continue;
    }
    double t1 = (-h - o[i]) / d[i];
    double t2 = (h - o[i]) / d[i];
    if (t1 > t2) std::swap(t1, t2);
    t_near = std::max(t_near, t1);
    t_far = std::min(t_far, t2);
    if (t_near > t_far) return std::nullopt;
  }
  const double t = t_near > 0.0 ? t_near : t_far;
  if (t <= 0.0 || t > max_range) return std::nullopt;
  return t;
}

double DistanceToRectangle(const Rectangle& r, const Eigen::Vector3d& p) {
  const Eigen::Vector3d q = p - r.center_m;
  const double u = std::clamp(q.dot(r.axis_u), -r.half_u_m, r.half_u_m);
  const double v = std::clamp(q.dot(r.axis_v), -r.half_v_m, r.half_v_m);
  return (q - u * r.axis_u - v * r.axis_v).norm();
}

double DistanceToBoxSurface(const Box& b, const Eigen::Vector3d& p) {
  const Eigen::Vector3d q = (b.T_world_box.inverse() * p).cwiseAbs();
  const Eigen::Vector3d outside = (q - b.half_extents_m).cwiseMax(0.0);
  if (outside.squaredNorm() > 0.0) return outside.norm();
  return (b.half_extents_m - q).minCoeff();
}

}  // namespace

void Scene::AddRectangle(const Rectangle& rectangle) {
  Rectangle r = rectangle;
  r.axis_u.normalize();
  r.axis_v = (r.axis_v - r.axis_v.dot(r.axis_u) * r.axis_u).normalized();
  rectangles_.push_back(r);
}

void Scene::AddBox(const Box& box) { boxes_.push_back(box); }

Eigen::Vector3d Motion::CentreAt(double t_s, const Eigen::Vector3d& fixed) const {
  if (path.empty()) return fixed;
  if (t_s <= path.front().first) return path.front().second;
  for (std::size_t i = 1; i < path.size(); ++i) {
    if (t_s <= path[i].first) {
      const double w = (t_s - path[i - 1].first) / (path[i].first - path[i - 1].first);
      return (1.0 - w) * path[i - 1].second + w * path[i].second;
    }
  }
  return path.back().second;
}

bool Scene::IsDynamic() const {
  for (const Rectangle& r : rectangles_) {
    if (!r.motion.IsStatic()) return true;
  }
  for (const Box& b : boxes_) {
    if (!b.motion.IsStatic()) return true;
  }
  return false;
}

Scene Scene::At(double t_s) const {
  Scene now;
  for (Rectangle r : rectangles_) {
    if (!r.motion.PresentAt(t_s)) continue;
    r.center_m = r.motion.CentreAt(t_s, r.center_m);
    now.rectangles_.push_back(std::move(r));
  }
  for (Box b : boxes_) {
    if (!b.motion.PresentAt(t_s)) continue;
    b.T_world_box.translation() = b.motion.CentreAt(t_s, b.T_world_box.translation());
    now.boxes_.push_back(std::move(b));
  }
  return now;
}

std::optional<RayHit> Scene::Raycast(const Eigen::Vector3d& origin_m,
                                     const Eigen::Vector3d& direction, double max_range_m) const {
  std::optional<RayHit> best;
  double best_t = max_range_m;
  for (std::size_t i = 0; i < rectangles_.size(); ++i) {
    const Rectangle& r = rectangles_[i];
    const Eigen::Vector3d n = r.Normal();
    const double denom = n.dot(direction);
    if (std::abs(denom) < 1e-12) continue;
    const double t = n.dot(r.center_m - origin_m) / denom;
    if (t <= 0.0 || t > best_t) continue;
    const Eigen::Vector3d q = origin_m + t * direction - r.center_m;
    if (std::abs(q.dot(r.axis_u)) > r.half_u_m || std::abs(q.dot(r.axis_v)) > r.half_v_m) continue;
    best_t = t;
    best = RayHit{t, r.textured, static_cast<int>(i)};
  }
  for (std::size_t i = 0; i < boxes_.size(); ++i) {
    const auto t = RayBox(boxes_[i], origin_m, direction, best_t);
    if (!t) continue;
    best_t = *t;
    best = RayHit{*t, boxes_[i].textured, static_cast<int>(rectangles_.size() + i)};
  }
  return best;
}

double Scene::DistanceToSurface(const Eigen::Vector3d& p_m) const {
  double d = std::numeric_limits<double>::infinity();
  for (const auto& r : rectangles_) d = std::min(d, DistanceToRectangle(r, p_m));
  for (const auto& b : boxes_) d = std::min(d, DistanceToBoxSurface(b, p_m));
  return d;
}

bool Scene::SurfaceIntersects(const Eigen::AlignedBox3d& box_m) const {
  // A surface that only touches the box along its edge (the board's rim on a voxel face) holds
  // no area of it: the surfaces are tested shrunk by kTouchM. A plane lying in a face still
  // counts (a rectangle has no thickness to shrink); a solid's face lying in a voxel's face
  // belongs to the voxel inside the solid.
  constexpr double kTouchM = 1e-9;
  for (const Rectangle& r : rectangles_) {
    if (RectangleIntersectsAabb(r, box_m, kTouchM)) return true;
  }
  for (const Box& b : boxes_) {
    if (!ObbOverlapsAabb(b, box_m, kTouchM)) continue;
    // Overlapping but entirely inside the solid: no surface passes through the
    // voxel.
    bool all_inside = true;
    for (int c = 0; c < 8 && all_inside; ++c) {
      all_inside =
          InsideBox(b, box_m.corner(static_cast<Eigen::AlignedBox3d::CornerType>(c)), kTouchM);
    }
    if (!all_inside) return true;
  }
  return false;
}

namespace {

bool ParseNumber(const std::string& token, double* x) {
  char* end = nullptr;
  *x = std::strtod(token.c_str(), &end);
  return end != token.c_str() && *end == '\0' && std::isfinite(*x);
}

// An object line after its kind and name: the numbers, then the keywords (untextured, from,
// until, path). Returns an error message, empty when the line is well formed.
struct ObjectLine {
  std::vector<double> numbers;
  bool textured = true;
  Motion motion;
};

std::string ParseObjectTail(const std::vector<std::string>& tokens, ObjectLine* out) {
  std::size_t i = 2;
  for (double x = 0.0; i < tokens.size() && ParseNumber(tokens[i], &x); ++i) out->numbers.push_back(x);
  while (i < tokens.size()) {
    const std::string& key = tokens[i++];
    double x = 0.0;
    if (key == "untextured") {
      out->textured = false;
    } else if (key == "from" || key == "until") {
      if (i >= tokens.size() || !ParseNumber(tokens[i], &x)) return key + " needs a time (s)";
      (key == "from" ? out->motion.from_s : out->motion.until_s) = x;
      ++i;
    } else if (key == "path") {
      for (; i + 3 < tokens.size() && ParseNumber(tokens[i], &x); i += 4) {
        Eigen::Vector3d c;
        for (int a = 0; a < 3; ++a) {
          if (!ParseNumber(tokens[i + 1 + a], &c[a])) return "path needs T X Y Z per waypoint";
        }
        if (!out->motion.path.empty() && x <= out->motion.path.back().first) {
          return "path times must ascend";
        }
        out->motion.path.emplace_back(x, c);
      }
      if (out->motion.path.empty()) return "path needs T X Y Z per waypoint";
    } else {
      double unused = 0.0;
      return ParseNumber(key, &unused) ? "too many numbers, or a path waypoint cut short"
                                       : "not a finite number or keyword: '" + key + "'";
    }
  }
  if (!(out->motion.from_s < out->motion.until_s)) return "from must come before until";
  return "";
}

std::string AddRect(const std::string& name, const ObjectLine& line, Scene* scene) {
  const std::vector<double>& v = line.numbers;
  if (v.size() != 11) return "rect needs: NAME cx cy cz ux uy uz vx vy vz size_u size_v [untextured]";
  Rectangle r;
  r.name = name;
  r.center_m = {v[0], v[1], v[2]};
  r.axis_u = {v[3], v[4], v[5]};
  r.axis_v = {v[6], v[7], v[8]};
  if (r.axis_u.norm() < 1e-9 || r.axis_v.norm() < 1e-9 ||
      r.axis_u.normalized().cross(r.axis_v.normalized()).norm() < 1e-6) {
    return "rect axes must be non-zero and not parallel";
  }
  if (v[9] <= 0.0 || v[10] <= 0.0) return "rect sizes must be positive";
  r.half_u_m = v[9] / 2.0;
  r.half_v_m = v[10] / 2.0;
  r.textured = line.textured;
  r.motion = line.motion;
  scene->AddRectangle(r);
  return "";
}

std::string AddBox(const std::string& name, const ObjectLine& line, Scene* scene) {
  const std::vector<double>& v = line.numbers;
  if (v.size() != 6 && v.size() != 9) {
    return "box needs: NAME cx cy cz sx sy sz [roll pitch yaw] [untextured]";
  }
  Box b;
  b.name = name;
  if (v[3] <= 0.0 || v[4] <= 0.0 || v[5] <= 0.0) return "box sizes must be positive";
  b.half_extents_m = Eigen::Vector3d(v[3], v[4], v[5]) / 2.0;
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
  if (v.size() == 9) {
    R = (Eigen::AngleAxisd(v[8] * kDegToRad, Eigen::Vector3d::UnitZ()) *
         Eigen::AngleAxisd(v[7] * kDegToRad, Eigen::Vector3d::UnitY()) *
         Eigen::AngleAxisd(v[6] * kDegToRad, Eigen::Vector3d::UnitX()))
            .toRotationMatrix();
  }
  b.T_world_box.linear() = R;
  b.T_world_box.translation() = Eigen::Vector3d(v[0], v[1], v[2]);
  b.textured = line.textured;
  b.motion = line.motion;
  scene->AddBox(b);
  return "";
}

}  // namespace

std::optional<Scene> ParseScene(const std::string& text, std::string* error) {
  Scene scene;
  std::istringstream lines(text);
  std::string line;
  int line_number = 0;
  while (std::getline(lines, line)) {
    ++line_number;
    const auto hash = line.find('#');
    if (hash != std::string::npos) line.resize(hash);
    std::istringstream in(line);
    std::vector<std::string> tokens;
    for (std::string t; in >> t;) tokens.push_back(t);
    if (tokens.empty()) continue;
    std::string why;
    ObjectLine object;
    if (tokens[0] != "rect" && tokens[0] != "box") {
      why = "unknown object '" + tokens[0] + "' (expected rect or box)";
    } else if (tokens.size() < 2) {
      why = tokens[0] + " needs a NAME";
    } else if (why = ParseObjectTail(tokens, &object); why.empty()) {
      why = tokens[0] == "rect" ? AddRect(tokens[1], object, &scene)
                                : AddBox(tokens[1], object, &scene);
    }
    if (!why.empty()) {
      if (error != nullptr) *error = "line " + std::to_string(line_number) + ": " + why;
      return std::nullopt;
    }
  }
  return scene;
}

std::optional<Scene> LoadSceneFile(const std::string& path, std::string* error) {
  std::ifstream file(path);
  if (!file) {
    if (error != nullptr) *error = "cannot open scene file '" + path + "'";
    return std::nullopt;
  }
  std::ostringstream text;
  text << file.rdbuf();
  return ParseScene(text.str(), error);
}

Scene PaperBoardScene() {
  Scene scene;
  Rectangle board;
  board.name = "board";
  board.center_m = {PaperSetup::kBoardDistanceM, 0.0,
                    PaperSetup::kBoardBottomZM + PaperSetup::kBoardHeightM / 2.0};
  board.axis_u = Eigen::Vector3d::UnitY();
  board.axis_v = Eigen::Vector3d::UnitZ();
  board.half_u_m = PaperSetup::kBoardWidthM / 2.0;
  board.half_v_m = PaperSetup::kBoardHeightM / 2.0;
  scene.AddRectangle(board);
  Rectangle floor;
  floor.name = "floor";
  floor.center_m = {2.0, 0.0, PaperSetup::kFloorZM};
  floor.axis_u = Eigen::Vector3d::UnitX();
  floor.axis_v = Eigen::Vector3d::UnitY();
  floor.half_u_m = 2.0;
  floor.half_v_m = 2.0;
  floor.textured = false;
  scene.AddRectangle(floor);
  return scene;
}

Eigen::Isometry3d ForwardLookingPose(const Eigen::Vector3d& position_m, double yaw_rad,
                                     double pitch_rad) {
  // Optical axes in a world frame x forward, y left, z up: x_opt = -y, y_opt =
  // -z, z_opt = +x.
  Eigen::Matrix3d R_world_optical;
  R_world_optical << 0, 0, 1, -1, 0, 0, 0, -1, 0;
  const Eigen::Matrix3d R_view = (Eigen::AngleAxisd(yaw_rad, Eigen::Vector3d::UnitZ()) *
                                  Eigen::AngleAxisd(pitch_rad, Eigen::Vector3d::UnitY()))
                                     .toRotationMatrix();
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = R_view * R_world_optical;
  T.translation() = position_m;
  return T;
}

}  // namespace fusion::sim
