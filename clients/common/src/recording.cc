#include "fusion/clients/recording.h"

#include <unistd.h>

#include <chrono>
#include <cstring>

#include "fusion/clients/crc32.h"

namespace fusion::clients {
namespace {

void PutLe32(std::uint32_t v, unsigned char* out) {
  for (int i = 0; i < 4; ++i) out[i] = static_cast<unsigned char>(v >> (8 * i));
}
void PutLe64(std::uint64_t v, unsigned char* out) {
  for (int i = 0; i < 8; ++i) out[i] = static_cast<unsigned char>(v >> (8 * i));
}
std::uint32_t GetLe32(const unsigned char* in) {
  std::uint32_t v = 0;
  for (int i = 0; i < 4; ++i) v |= static_cast<std::uint32_t>(in[i]) << (8 * i);
  return v;
}
std::uint64_t GetLe64(const unsigned char* in) {
  std::uint64_t v = 0;
  for (int i = 0; i < 8; ++i) v |= static_cast<std::uint64_t>(in[i]) << (8 * i);
  return v;
}

std::string Hex(std::uint32_t v) {
  char text[16];
  std::snprintf(text, sizeof text, "0x%08x", v);
  return text;
}

std::string RecordName(std::size_t i) { return "record " + std::to_string(i); }

}  // namespace

fusion::v1::RecordingIndexEntry MakeIndexEntry(const fusion::v1::RecordedCloud& cloud,
                                               std::uint64_t offset) {
  fusion::v1::RecordingIndexEntry entry;
  entry.set_offset(offset);
  *entry.mutable_stamp() = cloud.stamp();
  entry.set_receive_time_unix_ns(cloud.receive_time_unix_ns());
  entry.set_sensor_id(cloud.sensor_id());
  entry.set_sequence_number(cloud.sequence_number());
  return entry;
}

// ---------------------------------------------------------------------------------------------
// Writer

Status RecordingWriter::Create(const std::string& path, const std::string& writer,
                               const std::string& source, std::unique_ptr<RecordingWriter>* out) {
  std::FILE* file = std::fopen(path.c_str(), "wb");
  if (file == nullptr) return Status::Error("cannot create " + path + ": " + std::strerror(errno));
  std::unique_ptr<RecordingWriter> result(new RecordingWriter(path, file));
  fusion::v1::RecordingFrame frame;
  auto* header = frame.mutable_header();
  header->set_magic(kRecordingMagic);
  header->set_version(kRecordingVersion);
  header->set_created_unix_ns(std::chrono::duration_cast<std::chrono::nanoseconds>(
                                  std::chrono::system_clock::now().time_since_epoch())
                                  .count());
  header->set_writer(writer);
  header->set_source(source);
  if (Status s = result->WriteFrame(frame); !s.ok()) return s;
  if (std::fflush(file) != 0) return Status::Error("writing " + path + ": " + std::strerror(errno));
  *out = std::move(result);
  return Status::Ok();
}

RecordingWriter::~RecordingWriter() {
  if (file_ != nullptr) (void)Close();
}

Status RecordingWriter::WriteFrame(const fusion::v1::RecordingFrame& frame) {
  buffer_.clear();
  if (!frame.SerializeToString(&buffer_)) return Status::Error("cannot serialise a frame");
  if (buffer_.size() > kMaxFramePayloadBytes) {
    return Status::Error("frame of " + std::to_string(buffer_.size()) +
                         " bytes exceeds the format's limit");
  }
  unsigned char head[kFrameHeaderBytes];
  PutLe32(static_cast<std::uint32_t>(buffer_.size()), head);
  PutLe32(Crc32(buffer_.data(), buffer_.size()), head + 4);
  if (std::fwrite(head, 1, sizeof head, file_) != sizeof head ||
      std::fwrite(buffer_.data(), 1, buffer_.size(), file_) != buffer_.size()) {
    return Status::Error("writing " + path_ + ": " + std::strerror(errno));
  }
  offset_bytes_ += sizeof head + buffer_.size();
  return Status::Ok();
}

Status RecordingWriter::Append(const fusion::v1::RecordedCloud& cloud) {
  if (file_ == nullptr) return Status::Error(path_ + " is closed");
  const std::uint64_t offset = offset_bytes_;
  fusion::v1::RecordingFrame frame;
  *frame.mutable_cloud() = cloud;
  if (Status s = WriteFrame(frame); !s.ok()) return s;
  // Hand every record to the OS at once: a crash of this process then loses nothing.
  if (std::fflush(file_) != 0)
    return Status::Error("writing " + path_ + ": " + std::strerror(errno));
  *index_.add_entries() = MakeIndexEntry(cloud, offset);
  return Status::Ok();
}

Status RecordingWriter::Close() {
  if (file_ == nullptr) return Status::Ok();
  const std::uint64_t index_offset = offset_bytes_;
  fusion::v1::RecordingFrame frame;
  *frame.mutable_index() = index_;
  Status status = WriteFrame(frame);
  if (status.ok()) {
    unsigned char footer[kFooterBytes];
    PutLe64(index_offset, footer);
    std::memcpy(footer + 8, kFooterMagic, 8);
    if (std::fwrite(footer, 1, sizeof footer, file_) != sizeof footer || std::fflush(file_) != 0 ||
        fsync(fileno(file_)) != 0) {
      status = Status::Error("writing " + path_ + ": " + std::strerror(errno));
    }
    offset_bytes_ += kFooterBytes;
  }
  if (std::fclose(file_) != 0 && status.ok()) {
    status = Status::Error("closing " + path_ + ": " + std::strerror(errno));
  }
  file_ = nullptr;
  return status;
}

// ---------------------------------------------------------------------------------------------
// Reader

RecordingReader::~RecordingReader() {
  if (file_ != nullptr) std::fclose(file_);
}

Status RecordingReader::ReadFrame(std::uint64_t offset, const std::string& what,
                                  fusion::v1::RecordingFrame* frame, std::uint64_t* end) {
  const std::string where = what + " at byte " + std::to_string(offset) + ": ";
  if (offset > file_size_bytes_ || file_size_bytes_ - offset < kFrameHeaderBytes) {
    return Status::Error(where + "truncated (frame header needs 8 bytes, " +
                         std::to_string(file_size_bytes_ - std::min(offset, file_size_bytes_)) +
                         " left)");
  }
  unsigned char head[kFrameHeaderBytes];
  if (fseeko(file_, static_cast<off_t>(offset), SEEK_SET) != 0 ||
      std::fread(head, 1, sizeof head, file_) != sizeof head) {
    return Status::Error(where + "read error: " + std::strerror(errno));
  }
  const std::uint32_t length = GetLe32(head);
  const std::uint32_t stored_crc = GetLe32(head + 4);
  if (length > kMaxFramePayloadBytes) {
    return Status::Error(where + "implausible frame length " + std::to_string(length) +
                         " bytes (corrupt length field)");
  }
  const std::uint64_t left = file_size_bytes_ - offset - kFrameHeaderBytes;
  if (length > left) {
    return Status::Error(where + "truncated (payload of " + std::to_string(length) +
                         " bytes, only " + std::to_string(left) + " left)");
  }
  buffer_.resize(length);
  if (length > 0 && std::fread(buffer_.data(), 1, length, file_) != length) {
    return Status::Error(where + "read error: " + std::strerror(errno));
  }
  const std::uint32_t crc = Crc32(buffer_.data(), buffer_.size());
  if (crc != stored_crc) {
    return Status::Error(where + "crc mismatch (stored " + Hex(stored_crc) + ", computed " +
                         Hex(crc) + ")");
  }
  if (!frame->ParseFromString(buffer_)) {
    return Status::Error(where + "payload is not a RecordingFrame");
  }
  *end = offset + kFrameHeaderBytes + length;
  return Status::Ok();
}

Status RecordingReader::Open(const std::string& path, std::unique_ptr<RecordingReader>* out) {
  std::FILE* file = std::fopen(path.c_str(), "rb");
  if (file == nullptr) return Status::Error("cannot open " + path + ": " + std::strerror(errno));
  std::unique_ptr<RecordingReader> reader(new RecordingReader(file));
  if (fseeko(file, 0, SEEK_END) != 0) return Status::Error("cannot seek in " + path);
  reader->file_size_bytes_ = static_cast<std::uint64_t>(ftello(file));

  fusion::v1::RecordingFrame frame;
  std::uint64_t header_end = 0;
  if (Status s = reader->ReadFrame(0, "header", &frame, &header_end); !s.ok()) {
    return Status::Error(path + " is not a readable fusion recording: " + s.message());
  }
  if (!frame.has_header() || frame.header().magic() != kRecordingMagic) {
    return Status::Error(path + " is not a fusion recording (no header frame with magic '" +
                         kRecordingMagic + "')");
  }
  if (frame.header().version() != kRecordingVersion) {
    return Status::Error(path + ": recording format version " +
                         std::to_string(frame.header().version()) + " is not supported (only " +
                         std::to_string(kRecordingVersion) + ")");
  }
  reader->header_ = frame.header();
  if (Status s = reader->TryIndex(header_end); !s.ok()) {
    reader->index_note_ = s.message();
    reader->index_.Clear();
    reader->Scan(header_end);
  } else {
    reader->indexed_ = true;
  }
  *out = std::move(reader);
  return Status::Ok();
}

Status RecordingReader::TryIndex(std::uint64_t header_end) {
  if (file_size_bytes_ < header_end + kFooterBytes) return Status::Error("no index (no footer)");
  unsigned char footer[kFooterBytes];
  const std::uint64_t footer_offset = file_size_bytes_ - kFooterBytes;
  if (fseeko(file_, static_cast<off_t>(footer_offset), SEEK_SET) != 0 ||
      std::fread(footer, 1, sizeof footer, file_) != sizeof footer) {
    return Status::Error("no index (footer unreadable)");
  }
  if (std::memcmp(footer + 8, kFooterMagic, 8) != 0) {
    return Status::Error("no index (not closed cleanly: footer missing)");
  }
  const std::uint64_t index_offset = GetLe64(footer);
  if (index_offset < header_end || index_offset >= footer_offset) {
    return Status::Error("index offset " + std::to_string(index_offset) + " out of range");
  }
  fusion::v1::RecordingFrame frame;
  std::uint64_t end = 0;
  if (Status s = ReadFrame(index_offset, "index", &frame, &end); !s.ok()) return s;
  if (!frame.has_index() || end != footer_offset) {
    return Status::Error("index at byte " + std::to_string(index_offset) + " is not an index");
  }
  std::uint64_t previous_end = header_end;
  for (const auto& entry : frame.index().entries()) {
    // Offsets must be increasing and inside the records' area; otherwise distrust the index.
    if (entry.offset() < previous_end || entry.offset() + kFrameHeaderBytes > index_offset) {
      return Status::Error("index entry offset " + std::to_string(entry.offset()) +
                           " out of order or range");
    }
    previous_end = entry.offset() + kFrameHeaderBytes;
  }
  index_ = frame.index();
  return Status::Ok();
}

void RecordingReader::Scan(std::uint64_t header_end) {
  std::uint64_t offset = header_end;
  fusion::v1::RecordingFrame frame;
  while (offset < file_size_bytes_) {
    const std::size_t i = size();
    std::uint64_t end = 0;
    if (Status s = ReadFrame(offset, RecordName(i), &frame, &end); !s.ok()) {
      tail_error_ = s;
      return;
    }
    if (frame.has_index()) return;  // a complete index frame ends the records
    if (!frame.has_cloud()) {
      tail_error_ = Status::Error(RecordName(i) + " at byte " + std::to_string(offset) +
                                  ": unexpected frame kind (not a cloud)");
      return;
    }
    *index_.add_entries() = MakeIndexEntry(frame.cloud(), offset);
    offset = end;
  }
}

Status RecordingReader::Read(std::size_t i, fusion::v1::RecordedCloud* cloud) {
  if (i >= size()) {
    return Status::Error(RecordName(i) + ": out of range (" + std::to_string(size()) + " records)");
  }
  fusion::v1::RecordingFrame frame;
  std::uint64_t end = 0;
  const std::uint64_t offset = entry(i).offset();
  if (Status s = ReadFrame(offset, RecordName(i), &frame, &end); !s.ok()) return s;
  if (!frame.has_cloud()) {
    return Status::Error(RecordName(i) + " at byte " + std::to_string(offset) +
                         ": not a cloud frame");
  }
  *cloud = std::move(*frame.mutable_cloud());
  return Status::Ok();
}

}  // namespace fusion::clients
