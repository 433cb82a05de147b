// Points given in a robot's body frame (REP-103: x forward, y left, z up) re-expressed in the
// optical frame fusiond reads (x right, y down, z forward), their world positions kept.
#include <cmath>
#include <cstring>

#include "fusion/clients/importers.h"

namespace fusion::clients {

namespace {

// q_a * q_b (Hamilton), both as (x, y, z, w).
void Multiply(const double a[4], const double b[4], double out[4]) {
  out[0] = a[3] * b[0] + a[0] * b[3] + a[1] * b[2] - a[2] * b[1];
  out[1] = a[3] * b[1] - a[0] * b[2] + a[1] * b[3] + a[2] * b[0];
  out[2] = a[3] * b[2] + a[0] * b[1] - a[1] * b[0] + a[2] * b[3];
  out[3] = a[3] * b[3] - a[0] * b[0] - a[1] * b[1] - a[2] * b[2];
}

// R_body_optical: its columns, the optical axes in the body frame, are (0,-1,0), (0,0,-1),
// (1,0,0).
constexpr double kQBodyOptical[4] = {-0.5, 0.5, -0.5, 0.5};

}  // namespace

Status ParsePointFrame(const std::string& flag, const std::string& text, PointFrame* frame) {
  if (text == "optical") {
    *frame = PointFrame::kOptical;
  } else if (text == "body") {
    *frame = PointFrame::kBody;
  } else {
    return Status::Error(flag + ": expected optical or body, got '" + text + "'");
  }
  return Status::Ok();
}

void ToOpticalFrame(PointFrame frame, fusion::v1::RecordedCloud* cloud) {
  if (frame == PointFrame::kOptical) return;
  std::string& xyz = *cloud->mutable_xyz_f32le();
  for (std::size_t i = 0; i + 12 <= xyz.size(); i += 12) {
    float body[3];
    GetPoint(*cloud, i / 12, body);
    const float optical[3] = {-body[1], -body[2], body[0]};  // exact: signs and order only
    std::memcpy(&xyz[i], optical, sizeof optical);
  }
  auto* pose = cloud->mutable_t_world_sensor();
  const double q_world_body[4] = {pose->qx(), pose->qy(), pose->qz(), pose->qw()};
  double q[4];
  Multiply(q_world_body, kQBodyOptical, q);
  double norm = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
  if (!(norm > 0)) norm = 1;  // a zero quaternion stays zero (and is refused downstream)
  pose->set_qx(q[0] / norm);
  pose->set_qy(q[1] / norm);
  pose->set_qz(q[2] / norm);
  pose->set_qw(q[3] / norm);
}

}  // namespace fusion::clients
