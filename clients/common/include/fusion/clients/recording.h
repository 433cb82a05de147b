// Recording files: length-delimited, CRC-framed protobuf frames with an index at the end
// (layout and rationale in docs/recording-format.md).
//
//   file   = frame(header) frame(cloud)* [frame(index) footer]
//   frame  = uint32 payload_length_bytes (LE) | uint32 crc32(payload) (LE) | payload
//   footer = uint64 index_frame_offset (LE) | "FRECIDX1"
//
// A writer that dies leaves no index; every complete frame before the torn tail still reads.
#pragma once

#include <cstdint>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include "fusion/core/status.h"
#include "fusion/v1/recording.pb.h"

namespace fusion::clients {

inline constexpr const char* kRecordingMagic = "fusion-recording";
inline constexpr std::uint32_t kRecordingVersion = 1;
inline constexpr char kFooterMagic[9] = "FRECIDX1";
inline constexpr std::size_t kFrameHeaderBytes = 8;
inline constexpr std::size_t kFooterBytes = 16;
// A frame longer than this is treated as corruption (a 640x480 cloud is ~3.7 MB).
inline constexpr std::uint32_t kMaxFramePayloadBytes = 512u << 20;

class RecordingWriter {
 public:
  // Creates (or truncates) `path` and writes the header frame. `writer` and `source` go
  // into the header (tool name, where the clouds come from).
  static Status Create(const std::string& path, const std::string& writer,
                       const std::string& source, std::unique_ptr<RecordingWriter>* out);
  ~RecordingWriter();  // closes (writes the index) if Close() was not called
  RecordingWriter(const RecordingWriter&) = delete;
  RecordingWriter& operator=(const RecordingWriter&) = delete;

  // Appends one record and flushes it to the OS, so that a crash afterwards keeps it.
  Status Append(const fusion::v1::RecordedCloud& cloud);
  // Writes the index frame and the footer, flushes to disk and closes the file.
  Status Close();

  [[nodiscard]] std::uint64_t records_written() const { return index_.entries_size(); }
  [[nodiscard]] std::uint64_t bytes_written() const { return offset_bytes_; }
  [[nodiscard]] const std::string& path() const { return path_; }

 private:
  RecordingWriter(std::string path, std::FILE* file) : path_(std::move(path)), file_(file) {}
  Status WriteFrame(const fusion::v1::RecordingFrame& frame);

  std::string path_;
  std::FILE* file_ = nullptr;
  std::uint64_t offset_bytes_ = 0;
  fusion::v1::RecordingIndex index_;
  std::string buffer_;
};

// Reads a recording through its index, or by a sequential scan when the index is missing
// or damaged; a scan stops at the first broken frame and remembers why (tail_error()).
class RecordingReader {
 public:
  static Status Open(const std::string& path, std::unique_ptr<RecordingReader>* out);
  ~RecordingReader();
  RecordingReader(const RecordingReader&) = delete;
  RecordingReader& operator=(const RecordingReader&) = delete;

  [[nodiscard]] const fusion::v1::RecordingHeader& header() const { return header_; }
  // Number of records that can be read (all of them when indexed; those before the break
  // otherwise).
  [[nodiscard]] std::size_t size() const { return static_cast<std::size_t>(index_.entries_size()); }
  [[nodiscard]] const fusion::v1::RecordingIndexEntry& entry(std::size_t i) const {
    return index_.entries(static_cast<int>(i));
  }
  // True when the file's own index was used; false after a sequential scan.
  [[nodiscard]] bool indexed() const { return indexed_; }
  // Why the index was not used (empty when it was).
  [[nodiscard]] const std::string& index_note() const { return index_note_; }
  // Where the sequential scan stopped before the end of the file ("record 17 at byte 123456:
  // crc mismatch"); OK when it reached a clean end or the index was used.
  [[nodiscard]] const Status& tail_error() const { return tail_error_; }
  [[nodiscard]] std::uint64_t file_size_bytes() const { return file_size_bytes_; }

  // Reads record i (0-based), checking its CRC. Errors name the record and its byte offset.
  Status Read(std::size_t i, fusion::v1::RecordedCloud* cloud);

 private:
  explicit RecordingReader(std::FILE* file) : file_(file) {}
  // Reads the frame at `offset`; *end receives the offset after it. `what` names the frame
  // in errors.
  Status ReadFrame(std::uint64_t offset, const std::string& what, fusion::v1::RecordingFrame* frame,
                   std::uint64_t* end);
  Status TryIndex(std::uint64_t header_end);
  void Scan(std::uint64_t header_end);

  std::FILE* file_ = nullptr;
  std::uint64_t file_size_bytes_ = 0;
  fusion::v1::RecordingHeader header_;
  fusion::v1::RecordingIndex index_;
  bool indexed_ = false;
  std::string index_note_;
  Status tail_error_;
  std::string buffer_;
};

// Index entry of a cloud stored at `offset`.
fusion::v1::RecordingIndexEntry MakeIndexEntry(const fusion::v1::RecordedCloud& cloud,
                                               std::uint64_t offset);

}  // namespace fusion::clients
