#include "fusion/clients/cli.h"

#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <sstream>
#include <vector>

namespace fusion::clients {

Status ParseDouble(const std::string& flag, const std::string& text, double* value) {
  char* end = nullptr;
  errno = 0;
  const double v = std::strtod(text.c_str(), &end);
  if (text.empty() || end != text.c_str() + text.size() || errno != 0 || !std::isfinite(v)) {
    return Status::Error(flag + ": '" + text + "' is not a finite number");
  }
  *value = v;
  return Status::Ok();
}

Status ParseUint(const std::string& flag, const std::string& text, std::uint64_t* value) {
  char* end = nullptr;
  errno = 0;
  const unsigned long long v = std::strtoull(text.c_str(), &end, 10);
  if (text.empty() || text[0] == '-' || end != text.c_str() + text.size() || errno != 0) {
    return Status::Error(flag + ": '" + text + "' is not a non-negative integer");
  }
  *value = v;
  return Status::Ok();
}

Status ParsePose(const std::string& flag, const std::string& text, fusion::v1::RecordedPose* pose) {
  std::vector<double> values;
  std::stringstream stream(text);
  std::string item;
  while (std::getline(stream, item, ',')) {
    double v = 0;
    if (Status s = ParseDouble(flag, item, &v); !s.ok()) return s;
    values.push_back(v);
  }
  if (values.size() != 3 && values.size() != 7) {
    return Status::Error(flag + ": expected tx,ty,tz or tx,ty,tz,qx,qy,qz,qw, got '" + text + "'");
  }
  pose->set_tx(values[0]);
  pose->set_ty(values[1]);
  pose->set_tz(values[2]);
  double q[4] = {0, 0, 0, 1};
  if (values.size() == 7) {
    const double norm = std::sqrt(values[3] * values[3] + values[4] * values[4] +
                                  values[5] * values[5] + values[6] * values[6]);
    if (norm < 1e-9) return Status::Error(flag + ": the quaternion is zero");
    for (int i = 0; i < 4; ++i) q[i] = values[3 + i] / norm;
  }
  pose->set_qx(q[0]);
  pose->set_qy(q[1]);
  pose->set_qz(q[2]);
  pose->set_qw(q[3]);
  return Status::Ok();
}

fusion::v1::RecordedTime TimeFromSeconds(double seconds) {
  fusion::v1::RecordedTime time;
  double whole = std::floor(seconds);
  auto nanosec = static_cast<std::int64_t>(std::llround((seconds - whole) * 1e9));
  if (nanosec >= 1000000000) {
    whole += 1;
    nanosec -= 1000000000;
  }
  time.set_sec(static_cast<std::int32_t>(whole));
  time.set_nanosec(static_cast<std::uint32_t>(nanosec));
  return time;
}

Status ParseStamp(const std::string& what, const std::string& text,
                  fusion::v1::RecordedTime* time) {
  const std::size_t dot = text.find('.');
  const std::string whole = text.substr(0, dot);
  std::string fraction = dot == std::string::npos ? "" : text.substr(dot + 1);
  std::uint64_t sec = 0, nanosec = 0;
  const Status bad = Status::Error(what + ": '" + text + "' is not a time in seconds");
  if (!ParseUint(what, whole, &sec).ok() || sec > 0x7fffffffu || fraction.size() > 9) return bad;
  if (!fraction.empty() && !ParseUint(what, fraction, &nanosec).ok()) return bad;
  for (std::size_t i = fraction.size(); i < 9; ++i) nanosec *= 10;
  time->set_sec(static_cast<std::int32_t>(sec));
  time->set_nanosec(static_cast<std::uint32_t>(nanosec));
  return Status::Ok();
}

double SecondsFromTime(const fusion::v1::RecordedTime& time) {
  return static_cast<double>(time.sec()) + 1e-9 * static_cast<double>(time.nanosec());
}

}  // namespace fusion::clients
