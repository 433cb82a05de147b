// The bodies of the libFuzzer targets (tests/fuzz/fuzz_*.cc), in plain C++ so that the replay of
// tests/fuzz/regressions (tests/unit/fuzz) runs the very same code in the normal build.
//
// Each entry feeds `size` bytes of untrusted input to one parser the way the service or a
// client tool does, then checks what the parser accepted. An entry never throws.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace fusion::fuzz {

enum class Verdict {
  kAccepted,  // parsed; what came out passed the entry's checks
  kRejected,  // refused with an error message (the expected outcome for junk)
  kBroken,    // accepted but inconsistent, or refused without saying why: a bug
};

struct Outcome {
  Verdict verdict = Verdict::kRejected;
  std::string message;  // the parser's error, or what is inconsistent
};

using Entry = Outcome (*)(const std::uint8_t* data, std::size_t size);

// DDS ingest: a fusion_dds_PointCloud built from the bytes (Layout in entries/dds_sample.cc),
// ValidateSample, then CloudFromDds for the ones it accepts.
Outcome RunDdsSample(const std::uint8_t* data, std::size_t size);
// fusiond's configuration file: LoadConfigFile over DefaultConfig (text format / JSON).
Outcome RunConfigText(const std::uint8_t* data, std::size_t size);
Outcome RunConfigJson(const std::uint8_t* data, std::size_t size);
// A recording file: RecordingReader::Open, then every record read.
Outcome RunRecording(const std::uint8_t* data, std::size_t size);
// Importers (clients/common/importers.h).
Outcome RunPcd(const std::uint8_t* data, std::size_t size);
// groundtruth.txt, a NUL byte, then the bytes of the depth PNG the first line names.
Outcome RunTum(const std::uint8_t* data, std::size_t size);
Outcome RunXyzScan(const std::uint8_t* data, std::size_t size);
Outcome RunScanGraph(const std::uint8_t* data, std::size_t size);
// A map snapshot (.ot) through LoadSnapshotFile, the loader fusiond runs at start.
Outcome RunSnapshot(const std::uint8_t* data, std::size_t size);
// A serialized ROS 2 message (XCDR1) decoded as PointCloud2 (then PointsFromPointCloud2),
// Image (then PointsFromDepthImage), CameraInfo and TFMessage (fusion/ros2/cdr.h, points.h).
Outcome RunRos2Cdr(const std::uint8_t* data, std::size_t size);

struct NamedEntry {
  const char* target;  // fuzz target name without "fuzz_": the corpus and regressions folder
  Entry entry;
};
// Every entry, by target name.
const std::vector<NamedEntry>& AllEntries();

// Bytes of a DDS-sample input in RunDdsSample's layout (for seed corpora).
struct DdsSampleSeed {
  std::string sensor_id = "sr";
  std::uint32_t width = 2, height = 1;
  std::vector<float> xyz = {0.f, 0.f, 1.f, 0.f, 0.1f, 1.f};
  std::vector<std::uint8_t> beyond_range;
  double pose[7] = {0, 0, 0, 0, 0, 0, 1};  // tx ty tz qx qy qz qw
  double map_resolution_m = 0.05;
};
std::string EncodeDdsSample(const DdsSampleSeed& seed);

}  // namespace fusion::fuzz
