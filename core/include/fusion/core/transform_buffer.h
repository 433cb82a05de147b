// A buffer of timed rigid transforms between named frames, as ROS 2's tf2 keeps them: a tree of
// frames (each child has one parent), a bounded history per edge, and look-ups of the chain
// source -> common ancestor -> target at a time stamp, each dynamic edge interpolated between its
// neighbours in time (translation linearly, rotation by slerp), static edges valid at all times.
//
// Pure maths: no transport, no logging. Not thread-safe; callers that share one buffer between
// threads hold a lock around Add and Lookup.
#pragma once

#include <Eigen/Geometry>
#include <cstddef>
#include <deque>
#include <string>
#include <unordered_map>

namespace fusion {

enum class TransformStatus {
  kOk,
  kNoTransform,    // a frame is unknown, or the two frames are not connected
  kTooOld,         // the stamp lies before an edge's oldest kept transform
  kExtrapolation,  // the stamp lies after an edge's newest transform
};

// "ok", "no_transform", "transform_too_old", "extrapolation".
[[nodiscard]] const char* TransformStatusName(TransformStatus status);

class TransformBuffer {
 public:
  static constexpr double kDefaultHistoryS = 10.0;
  static constexpr std::size_t kDefaultMaxPerEdge = 1000;

  // history_s: dynamic transforms older than the edge's newest minus history_s are dropped;
  // max_per_edge: at most this many kept per edge (the oldest dropped). Throws
  // std::invalid_argument for history_s <= 0 (or not finite) or max_per_edge == 0.
  explicit TransformBuffer(double history_s = kDefaultHistoryS,
                           std::size_t max_per_edge = kDefaultMaxPerEdge);

  // T_parent_child: pose of child_frame in parent_frame (a point in child coordinates times it is
  // the point in parent coordinates); stamp_s in seconds (ROS time: sec + 1e-9 nanosec). A static
  // transform replaces the edge's value for all times; a dynamic one joins the edge's history in
  // time order (one at an equal stamp replaces it). A child given another parent, or switched
  // between static and dynamic, starts a fresh edge. Ignored: empty or equal frame names, a
  // non-finite stamp or transform, an edge that would close a loop.
  void Add(const std::string& parent_frame, const std::string& child_frame, double stamp_s,
           const Eigen::Isometry3d& T_parent_child, bool is_static);

  // T_target_source at stamp_s: pose of source_frame in target_frame. Equal frames give the
  // identity. *T_target_source is written only for kOk. Where several edges of the chain fail,
  // the status of the first one met walking from the source is returned. A stamp within a
  // microsecond of an edge's oldest or newest transform counts as at it (stamps of the epoch
  // are only that exact as doubles).
  [[nodiscard]] TransformStatus Lookup(const std::string& target_frame,
                                       const std::string& source_frame, double stamp_s,
                                       Eigen::Isometry3d* T_target_source) const;

 private:
  struct Sample {
    double stamp_s;
    Eigen::Vector3d translation;
    Eigen::Quaterniond rotation;
  };
  struct Edge {
    std::string parent;
    bool is_static = false;
    std::deque<Sample> samples;  // ascending stamps; one sample for a static edge
  };

  // T_parent_child of `edge` at stamp_s.
  static TransformStatus Interpolate(const Edge& edge, double stamp_s,
                                     Eigen::Isometry3d* T_parent_child);
  // True when `ancestor` is `frame` or lies on the way from `frame` to its root.
  [[nodiscard]] bool IsAncestor(const std::string& ancestor, const std::string& frame) const;
  // T_ancestor_frame, the edges from `frame` up to `ancestor` (which must be on the way).
  TransformStatus ChainTo(const std::string& ancestor, const std::string& frame, double stamp_s,
                          Eigen::Isometry3d* T_ancestor_frame) const;

  double history_s_;
  std::size_t max_per_edge_;
  std::unordered_map<std::string, Edge> edges_;  // by child frame
};

}  // namespace fusion
