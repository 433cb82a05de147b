// OctoMap binary scan graphs through ReadScanGraph (its layout check, then OctoMap's reader).
#include <vector>

#include "cloud_checks.h"
#include "fusion/clients/importers.h"

namespace fusion::fuzz {

Outcome RunScanGraph(const std::uint8_t* data, std::size_t size) {
  const std::string path = WriteScratch("scan.graph", data, size);
  if (path.empty()) return Broken("cannot write the scratch file");
  std::vector<fusion::v1::RecordedCloud> clouds;
  if (fusion::Status s = clients::ReadScanGraph(path, &clouds); !s.ok()) {
    return Rejected(s.message());
  }
  if (clouds.empty()) return Broken("accepted a graph without nodes");
  for (const auto& cloud : clouds) {
    if (cloud.height() != 1) return Broken("graph cloud is not one row");
    if (Outcome o = CheckShape(cloud); o.verdict == Verdict::kBroken) return o;
  }
  return Accepted();
}

}  // namespace fusion::fuzz
