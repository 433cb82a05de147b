// PCD files (ascii, binary, binary_compressed) through ReadPcd, as fusion-import reads them.
#include "cloud_checks.h"
#include "fusion/clients/importers.h"

namespace fusion::fuzz {

Outcome RunPcd(const std::uint8_t* data, std::size_t size) {
  const std::string path = WriteScratch("input.pcd", data, size);
  if (path.empty()) return Broken("cannot write the scratch file");
  fusion::v1::RecordedCloud cloud;
  if (fusion::Status s = clients::ReadPcd(path, &cloud); !s.ok()) return Rejected(s.message());
  if (cloud.width() == 0 || cloud.height() == 0) return Broken("accepted an empty cloud");
  if (Outcome o = CheckShape(cloud); o.verdict == Verdict::kBroken) return o;
  return CheckUnitPose(cloud.t_world_sensor());
}

}  // namespace fusion::fuzz
