// Helpers of the importer tests (tum_import_test.cc, pcd_import_test.cc,
// scan_import_test.cc): the shared sample data, temporary files, sensor-to-world transforms.
#pragma once

#include <gtest/gtest.h>
#include <unistd.h>

#include <fstream>
#include <string>

#include "fusion/v1/recording.pb.h"

// The importer tests are in this namespace too: they use these names unqualified.
namespace fusion::clients::import_test {

// ../shared/data: real samples (tests skip when one is absent).
inline const std::string kData = FUSION_SHARED_DATA_DIR;

inline bool Exists(const std::string& path) { return access(path.c_str(), R_OK) == 0; }

// A file name of this test process's own (tests may run in parallel).
inline std::string TempPath(const std::string& name) {
  return ::testing::TempDir() + "/" + std::to_string(getpid()) + "_" + name;
}

inline void WriteFile(const std::string& path, const std::string& bytes) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
}

// World point of a sensor-frame point: R(q) p + t.
inline void ToWorld(const fusion::v1::RecordedPose& T, const float p[3], double out[3]) {
  const double x = T.qx(), y = T.qy(), z = T.qz(), w = T.qw();
  const double R[3][3] = {{1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)},
                          {2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)},
                          {2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)}};
  const double t[3] = {T.tx(), T.ty(), T.tz()};
  for (int r = 0; r < 3; ++r) out[r] = R[r][0] * p[0] + R[r][1] * p[1] + R[r][2] * p[2] + t[r];
}

}  // namespace fusion::clients::import_test
