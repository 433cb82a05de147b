// Plain "x y z" scans with NODE lines through ReadXyzScan (never the .bz2 path: no bzip2
// process per input).
#include <vector>

#include "cloud_checks.h"
#include "fusion/clients/importers.h"

namespace fusion::fuzz {

Outcome RunXyzScan(const std::uint8_t* data, std::size_t size) {
  const std::string path = WriteScratch("scan.txt", data, size);
  if (path.empty()) return Broken("cannot write the scratch file");
  fusion::v1::RecordedPose pose;
  pose.set_qw(1.0);
  std::vector<fusion::v1::RecordedCloud> clouds;
  if (fusion::Status s = clients::ReadXyzScan(path, pose, &clouds); !s.ok()) {
    return Rejected(s.message());
  }
  if (clouds.empty()) return Broken("accepted a scan without clouds");
  for (const auto& cloud : clouds) {
    if (cloud.height() != 1) return Broken("scan cloud is not one row");
    if (Outcome o = CheckShape(cloud); o.verdict == Verdict::kBroken) return o;
    if (Outcome o = CheckUnitPose(cloud.t_world_sensor()); o.verdict == Verdict::kBroken) return o;
  }
  return Accepted();
}

}  // namespace fusion::fuzz
