#include "fusion/core/transform_buffer.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace fusion {
namespace {

// Stamps of the epoch (1.7e9 s) are exact to ~0.2 us as doubles: two conversions of one ROS time
// may differ by an ulp, so the ends of an edge's history are this lenient.
constexpr double kStampToleranceS = 1e-6;

bool IsFinite(const Eigen::Isometry3d& T) { return T.matrix().allFinite(); }

}  // namespace

const char* TransformStatusName(TransformStatus status) {
  switch (status) {
    case TransformStatus::kOk:
      return "ok";
    case TransformStatus::kNoTransform:
      return "no_transform";
    case TransformStatus::kTooOld:
      return "transform_too_old";
    case TransformStatus::kExtrapolation:
      return "extrapolation";
  }
  return "unknown";
}

TransformBuffer::TransformBuffer(double history_s, std::size_t max_per_edge)
    : history_s_(history_s), max_per_edge_(max_per_edge) {
  if (!(std::isfinite(history_s) && history_s > 0.0)) {
    throw std::invalid_argument("TransformBuffer: history_s must be finite and > 0");
  }
  if (max_per_edge == 0) throw std::invalid_argument("TransformBuffer: max_per_edge must be > 0");
}

bool TransformBuffer::IsAncestor(const std::string& ancestor, const std::string& frame) const {
  const std::string* current = &frame;
  // The tree has no loops (Add refuses them); the bound only guards the walk.
  for (std::size_t steps = 0; steps <= edges_.size(); ++steps) {
    if (*current == ancestor) return true;
    const auto it = edges_.find(*current);
    if (it == edges_.end()) return false;
    current = &it->second.parent;
  }
  return false;
}

void TransformBuffer::Add(const std::string& parent_frame, const std::string& child_frame,
                          double stamp_s, const Eigen::Isometry3d& T_parent_child, bool is_static) {
  if (parent_frame.empty() || child_frame.empty() || parent_frame == child_frame) return;
  if (!std::isfinite(stamp_s) || !IsFinite(T_parent_child)) return;
  // The rotation part of the linear part (polar decomposition): a matrix made from a quaternion
  // that was a little off unit (float on the wire) is a scaled rotation.
  if (!(std::abs(T_parent_child.linear().determinant()) > 1e-12)) return;
  // (Isometry3d::rotation() would return the linear part as it is.)
  Eigen::Matrix3d R_parent_child;
  T_parent_child.computeRotationScaling(&R_parent_child, static_cast<Eigen::Matrix3d*>(nullptr));
  Eigen::Quaterniond rotation(R_parent_child);
  rotation.normalize();
  const Sample sample{stamp_s, T_parent_child.translation(), rotation};

  auto it = edges_.find(child_frame);
  if (it == edges_.end() || it->second.parent != parent_frame ||
      it->second.is_static != is_static) {
    // A new parent must not lie below the child: that would close a loop.
    if (IsAncestor(child_frame, parent_frame)) return;
    it = edges_.try_emplace(child_frame).first;
    it->second.parent = parent_frame;
    it->second.is_static = is_static;
    it->second.samples.clear();
  }
  Edge& edge = it->second;
  if (is_static) {
    edge.samples.assign(1, sample);
    return;
  }
  auto& samples = edge.samples;
  const auto at = std::lower_bound(samples.begin(), samples.end(), stamp_s,
                                   [](const Sample& s, double t) { return s.stamp_s < t; });
  if (at != samples.end() && at->stamp_s == stamp_s) {
    *at = sample;
  } else {
    samples.insert(at, sample);
  }
  while (samples.size() > max_per_edge_) samples.pop_front();
  const double oldest_kept_s = samples.back().stamp_s - history_s_;
  while (samples.front().stamp_s < oldest_kept_s) samples.pop_front();
}

TransformStatus TransformBuffer::Interpolate(const Edge& edge, double stamp_s,
                                             Eigen::Isometry3d* T_parent_child) {
  const auto& samples = edge.samples;
  const Sample* a = &samples.front();
  const Sample* b = a;
  if (!edge.is_static) {
    if (stamp_s < samples.front().stamp_s - kStampToleranceS) return TransformStatus::kTooOld;
    if (stamp_s > samples.back().stamp_s + kStampToleranceS) {
      return TransformStatus::kExtrapolation;
    }
    const auto after = std::lower_bound(samples.begin(), samples.end(), stamp_s,
                                        [](const Sample& s, double t) { return s.stamp_s < t; });
    if (after == samples.end()) {
      a = b = &samples.back();
    } else if (after == samples.begin()) {
      a = b = &samples.front();
    } else {
      a = &*(after - 1);
      b = &*after;
    }
  }
  double t = 0.0;
  if (b->stamp_s > a->stamp_s) {
    t = std::clamp((stamp_s - a->stamp_s) / (b->stamp_s - a->stamp_s), 0.0, 1.0);
  }
  T_parent_child->setIdentity();
  T_parent_child->linear() = a->rotation.slerp(t, b->rotation).toRotationMatrix();
  T_parent_child->translation() = (1.0 - t) * a->translation + t * b->translation;
  return TransformStatus::kOk;
}

TransformStatus TransformBuffer::ChainTo(const std::string& ancestor, const std::string& frame,
                                         double stamp_s,
                                         Eigen::Isometry3d* T_ancestor_frame) const {
  Eigen::Isometry3d T_current_frame = Eigen::Isometry3d::Identity();
  const std::string* current = &frame;
  while (*current != ancestor) {
    const Edge& edge = edges_.at(*current);
    Eigen::Isometry3d T_parent_current;
    const TransformStatus status = Interpolate(edge, stamp_s, &T_parent_current);
    if (status != TransformStatus::kOk) return status;
    T_current_frame = T_parent_current * T_current_frame;
    current = &edge.parent;
  }
  *T_ancestor_frame = T_current_frame;
  return TransformStatus::kOk;
}

TransformStatus TransformBuffer::Lookup(const std::string& target_frame,
                                        const std::string& source_frame, double stamp_s,
                                        Eigen::Isometry3d* T_target_source) const {
  if (target_frame == source_frame) {
    T_target_source->setIdentity();
    return TransformStatus::kOk;
  }
  if (!std::isfinite(stamp_s)) return TransformStatus::kNoTransform;
  // The common ancestor: the first frame on the source's way up that is on the target's.
  const std::string* ancestor = &source_frame;
  for (std::size_t steps = 0;; ++steps) {
    if (steps > edges_.size()) return TransformStatus::kNoTransform;
    if (IsAncestor(*ancestor, target_frame)) break;
    const auto it = edges_.find(*ancestor);
    if (it == edges_.end()) return TransformStatus::kNoTransform;
    ancestor = &it->second.parent;
  }
  Eigen::Isometry3d T_ancestor_source;
  Eigen::Isometry3d T_ancestor_target;
  TransformStatus status = ChainTo(*ancestor, source_frame, stamp_s, &T_ancestor_source);
  if (status != TransformStatus::kOk) return status;
  status = ChainTo(*ancestor, target_frame, stamp_s, &T_ancestor_target);
  if (status != TransformStatus::kOk) return status;
  *T_target_source = T_ancestor_target.inverse(Eigen::Isometry) * T_ancestor_source;
  return TransformStatus::kOk;
}

}  // namespace fusion
