#include "fuzz_entries.h"

namespace fusion::fuzz {

const std::vector<NamedEntry>& AllEntries() {
  static const std::vector<NamedEntry> entries = {
      {"dds_sample", RunDdsSample},
      {"config_text", RunConfigText},
      {"config_json", RunConfigJson},
      {"recording", RunRecording},
      {"pcd", RunPcd},
      {"tum", RunTum},
      {"xyz_scan", RunXyzScan},
      {"scan_graph", RunScanGraph},
      {"snapshot", RunSnapshot},
      {"ros2_cdr", RunRos2Cdr},
  };
  return entries;
}

}  // namespace fusion::fuzz
