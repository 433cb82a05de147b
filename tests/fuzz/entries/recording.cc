// A recording file as fusion-replay opens it: the index (or a scan), then every record.
// Inputs of even length get their frames' CRCs recomputed (FixRecordingCrcs), so that the
// fuzzer reaches the frames' contents; odd lengths keep theirs (the mismatch paths).
#include "fusion/clients/recording.h"

#include <memory>

#include "common.h"

namespace fusion::fuzz {

Outcome RunRecording(const std::uint8_t* data, std::size_t size) {
  std::string bytes(reinterpret_cast<const char*>(data), size);
  if (size % 2 == 0) FixRecordingCrcs(&bytes);
  const std::string path = WriteScratch("input.frec", bytes.data(), bytes.size());
  if (path.empty()) return Broken("cannot write the scratch file");
  std::unique_ptr<clients::RecordingReader> reader;
  if (fusion::Status s = clients::RecordingReader::Open(path, &reader); !s.ok()) {
    return Rejected(s.message());
  }
  if (reader == nullptr) return Broken("Open succeeded without a reader");
  // Every index entry takes at least a few bytes of the file: the count is bounded by its size.
  if (reader->size() > reader->file_size_bytes()) return Broken("more records than bytes");
  for (std::size_t i = 0; i < reader->size(); ++i) {
    fusion::v1::RecordedCloud cloud;
    if (fusion::Status s = reader->Read(i, &cloud); !s.ok() && s.message().empty()) {
      return Broken("record " + std::to_string(i) + " failed without a message");
    }
  }
  if (!reader->tail_error().ok() && reader->tail_error().message().empty()) {
    return Broken("tail error without a message");
  }
  return Accepted();
}

}  // namespace fusion::fuzz
