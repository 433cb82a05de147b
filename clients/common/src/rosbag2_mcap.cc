// MCAP storage (https://mcap.dev/spec), read front to back without its index: magic, then
// records (opcode uint8, content length uint64, content) up to the Footer and the closing
// magic. Chunks are decompressed ("", "zstd", "lz4" frame format) and their records read in
// turn. CRCs are checked where the file has them (non-zero): chunk records, attachments, the
// data section (DataEnd) and the summary (Footer). All integers little-endian.
#include <lz4frame.h>
#include <zstd.h>

#include <cerrno>
#include <cstring>
#include <unordered_map>

#include "fusion/clients/crc32.h"
#include "fusion/clients/rosbag2.h"

namespace fusion::clients {
namespace {

constexpr std::uint8_t kMagic[8] = {0x89, 'M', 'C', 'A', 'P', '0', '\r', '\n'};
constexpr std::size_t kRecordHeaderBytes = 9;
constexpr std::uint64_t kMaxChunkBytes = std::uint64_t{1} << 30;  // uncompressed

enum Opcode : std::uint8_t {
  kHeader = 0x01,
  kFooter = 0x02,
  kSchema = 0x03,
  kChannel = 0x04,
  kMessage = 0x05,
  kChunk = 0x06,
  kMessageIndex = 0x07,
  kChunkIndex = 0x08,
  kAttachment = 0x09,
  kAttachmentIndex = 0x0A,
  kStatistics = 0x0B,
  kMetadata = 0x0C,
  kMetadataIndex = 0x0D,
  kSummaryOffset = 0x0E,
  kDataEnd = 0x0F,
};

const char* OpcodeName(std::uint8_t op) {
  static const char* const kNames[] = {
      "Header",     "Footer",       "Schema",        "Channel",       "Message",
      "Chunk",      "MessageIndex", "ChunkIndex",    "Attachment",    "AttachmentIndex",
      "Statistics", "Metadata",     "MetadataIndex", "SummaryOffset", "DataEnd"};
  return op >= 1 && op <= 0x0F ? kNames[op - 1] : "unknown";
}

// Fields of one record's content, every read checked against its end.
class Fields {
 public:
  Fields(const std::uint8_t* data, std::size_t size) : data_(data), size_(size) {}
  template <class T>
  bool Int(T* value) {
    if (size_ - pos_ < sizeof(T)) return false;
    std::memcpy(value, data_ + pos_, sizeof(T));  // little-endian hosts (cloud_points.cc)
    pos_ += sizeof(T);
    return true;
  }
  // uint32 length + bytes (strings, schema data, maps) or uint64 length + bytes.
  template <class Length>
  bool Sized(ros2::ByteView* bytes) {
    Length length = 0;
    if (!Int(&length) || length > size_ - pos_) return false;
    *bytes = ros2::ByteView(data_ + pos_, static_cast<std::size_t>(length));
    pos_ += static_cast<std::size_t>(length);
    return true;
  }
  bool String(std::string* text) {
    ros2::ByteView bytes;
    if (!Sized<std::uint32_t>(&bytes)) return false;
    text->assign(reinterpret_cast<const char*>(bytes.data), bytes.size);
    return true;
  }
  [[nodiscard]] std::size_t pos() const { return pos_; }
  [[nodiscard]] ros2::ByteView rest() const { return {data_ + pos_, size_ - pos_}; }

 private:
  const std::uint8_t* data_;
  std::size_t size_, pos_ = 0;
};

// The size checks come first: a damaged size is refused before it is allocated (zstd frames
// carry their content size; lz4 expands at most ~255 times).
Status CheckChunkSize(const std::string& compression, ros2::ByteView in, std::uint64_t size) {
  if (compression != "" && compression != "zstd" && compression != "lz4") {
    return Status::Error("compression '" + compression + "' is not supported (\"\", zstd, lz4)");
  }
  if (size > kMaxChunkBytes) {
    return Status::Error("uncompressed size " + std::to_string(size) + " is over 1 GiB");
  }
  if (compression.empty() && in.size != size) {
    return Status::Error("uncompressed records of " + std::to_string(in.size) +
                         " bytes, the chunk says " + std::to_string(size));
  }
  if (compression == "zstd") {
    const unsigned long long content = ZSTD_getFrameContentSize(in.data, in.size);
    if (content == ZSTD_CONTENTSIZE_ERROR) return Status::Error("zstd: not a zstd frame");
    if (content != ZSTD_CONTENTSIZE_UNKNOWN && content != size) {
      return Status::Error("zstd frame holds " + std::to_string(content) +
                           " bytes, the chunk says " + std::to_string(size));
    }
  }
  if (compression == "lz4" && size > 256 * std::uint64_t{in.size} + 1024) {
    return Status::Error("lz4: " + std::to_string(in.size) + " bytes cannot hold " +
                         std::to_string(size));
  }
  return Status::Ok();
}

// One LZ4 frame into *out (sized already); *written bytes come out.
Status Lz4Frame(ros2::ByteView in, std::vector<std::uint8_t>* out, std::size_t* written) {
  LZ4F_dctx* dctx = nullptr;
  if (LZ4F_isError(LZ4F_createDecompressionContext(&dctx, LZ4F_VERSION))) {
    return Status::Error("lz4: no decompression context");
  }
  std::size_t done_in = 0, done_out = 0, hint = 1;
  while (hint != 0 && done_in < in.size) {
    std::size_t in_bytes = in.size - done_in, out_bytes = out->size() - done_out;
    hint = LZ4F_decompress(dctx, out->data() + done_out, &out_bytes, in.data + done_in, &in_bytes,
                           nullptr);
    if (LZ4F_isError(hint)) {
      LZ4F_freeDecompressionContext(dctx);
      return Status::Error(std::string("lz4: ") + LZ4F_getErrorName(hint));
    }
    done_in += in_bytes, done_out += out_bytes;
    if (in_bytes == 0 && out_bytes == 0) break;  // output full, frame not done
  }
  LZ4F_freeDecompressionContext(dctx);
  if (hint != 0) return Status::Error("lz4: the frame is cut short");
  *written = done_out;
  return Status::Ok();
}

// A chunk's records: `size` bytes from `in` compressed with `compression`.
Status Decompress(const std::string& compression, ros2::ByteView in, std::uint64_t size,
                  std::vector<std::uint8_t>* out) {
  if (Status s = CheckChunkSize(compression, in, size); !s.ok()) return s;
  out->resize(static_cast<std::size_t>(size));
  std::size_t written = in.size;
  if (compression.empty()) {
    if (size != 0) std::memcpy(out->data(), in.data, in.size);
  } else if (compression == "zstd") {
    written = ZSTD_decompress(out->data(), out->size(), in.data, in.size);
    if (ZSTD_isError(written)) {
      return Status::Error(std::string("zstd: ") + ZSTD_getErrorName(written));
    }
  } else if (Status s = Lz4Frame(in, out, &written); !s.ok()) {
    return s;
  }
  if (written != size) {
    return Status::Error(compression + " gave " + std::to_string(written) +
                         " bytes, the chunk says " + std::to_string(size));
  }
  return Status::Ok();
}

class McapStorage final : public BagStorage {
 public:
  ~McapStorage() override {
    if (file_ != nullptr) std::fclose(file_);
  }

  Status Open(const std::string& path) {
    path_ = path;
    file_ = std::fopen(path.c_str(), "rb");
    if (file_ == nullptr) return Status::Error(path + ": cannot open: " + std::strerror(errno));
    std::fseek(file_, 0, SEEK_END);
    file_size_ = static_cast<std::uint64_t>(std::ftell(file_));
    std::fseek(file_, 0, SEEK_SET);
    std::uint8_t magic[8];
    if (std::fread(magic, 1, 8, file_) != 8 || std::memcmp(magic, kMagic, 8) != 0) {
      return Status::Error(path + ": no MCAP magic at the start");
    }
    data_crc_ = Crc32(magic, 8);
    offset_ = 8;
    return Status::Ok();
  }

  const std::vector<BagTopic>& topics() const override { return topics_; }

  Status Next(BagMessage* message, bool* end) override {
    *end = false;
    while (true) {
      if (in_chunk_) {
        bool found = false;
        if (Status s = NextInChunk(message, &found); !s.ok() || found) return s;
        in_chunk_ = false;
        continue;
      }
      if (done_) {
        *end = true;
        return Status::Ok();
      }
      bool found = false;
      if (Status s = NextRecord(message, &found); !s.ok() || found) return s;
    }
  }

 private:
  // "x.mcap: record 7 (Chunk) at byte 1234: " (with the messages returned so far at the end).
  Status RecordError(const std::string& what) const {
    return Status::Error(path_ + ": record " + std::to_string(record_) + " (" + OpcodeName(op_) +
                         ") at byte " + std::to_string(record_offset_) + ": " + what + " (after " +
                         std::to_string(messages_) + " messages)");
  }

  // Reads the next top-level record into content_ and handles it.
  Status NextRecord(BagMessage* message, bool* found) {
    record_ = next_record_++;
    record_offset_ = offset_;
    op_ = 0;
    if (offset_ == file_size_) {
      return Status::Error(path_ + ": the file ends at byte " + std::to_string(offset_) +
                           " after record " + std::to_string(record_ - 1) +
                           " without its Footer (truncated after " + std::to_string(messages_) +
                           " messages)");
    }
    std::uint8_t head[kRecordHeaderBytes];
    if (file_size_ - offset_ < kRecordHeaderBytes ||
        std::fread(head, 1, sizeof head, file_) != sizeof head) {
      return RecordError("record header runs past the end of the file (truncated)");
    }
    op_ = head[0];
    std::uint64_t length = 0;
    std::memcpy(&length, head + 1, 8);
    if (length > file_size_ - offset_ - kRecordHeaderBytes) {
      return RecordError("content of " + std::to_string(length) +
                         " bytes runs past the end of the " + std::to_string(file_size_) +
                         "-byte file (truncated)");
    }
    content_.resize(static_cast<std::size_t>(length));
    if (length != 0 && std::fread(content_.data(), 1, content_.size(), file_) != content_.size()) {
      return RecordError("read error");
    }
    offset_ += kRecordHeaderBytes + length;
    if (!after_data_end_) {
      if (op_ == kDataEnd) {
        expected_data_crc_ = data_crc_;
      } else {
        data_crc_ = Crc32(head, sizeof head, data_crc_);
        data_crc_ = Crc32(content_.data(), content_.size(), data_crc_);
      }
    } else if (op_ != kFooter) {
      summary_crc_ = Crc32(head, sizeof head, summary_crc_);
      summary_crc_ = Crc32(content_.data(), content_.size(), summary_crc_);
    }
    return Handle(ros2::ByteView(content_), head, message, found);
  }

  Status Handle(ros2::ByteView content, const std::uint8_t* head, BagMessage* message,
                bool* found) {
    Fields f(content.data, content.size);
    switch (op_) {
      case kSchema:
        return ReadSchema(&f).WithContext(Where());
      case kChannel:
        return ReadChannel(&f).WithContext(Where());
      case kMessage: {
        Status s = ReadMessage(&f, message);
        *found = s.ok();
        return s.ok() ? s : RecordError(s.message());
      }
      case kChunk:
        return OpenChunk(&f);
      case kAttachment:
        return CheckAttachment(content);
      case kDataEnd: {
        std::uint32_t crc = 0;
        if (!f.Int(&crc)) return RecordError("too short");
        if (crc != 0 && crc != expected_data_crc_) return RecordError("data section CRC mismatch");
        after_data_end_ = true;
        summary_start_ = offset_;
        return Status::Ok();
      }
      case kFooter:
        return CheckFooter(&f, head);
      default:
        return Status::Ok();  // Header, indexes, statistics, metadata, unknown opcodes
    }
  }

  std::string Where() const {
    return path_ + ": record " + std::to_string(record_) + " (" + OpcodeName(op_) + ") at byte " +
           std::to_string(record_offset_);
  }

  Status ReadSchema(Fields* f) {
    std::uint16_t id = 0;
    std::string name, encoding;
    ros2::ByteView data;
    if (!(f->Int(&id) && f->String(&name) && f->String(&encoding) &&
          f->Sized<std::uint32_t>(&data))) {
      return Status::Error("Schema is cut short");
    }
    schemas_[id] = name;
    return Status::Ok();
  }

  Status ReadChannel(Fields* f) {
    std::uint16_t id = 0, schema = 0;
    std::string topic, encoding;
    ros2::ByteView metadata;
    if (!(f->Int(&id) && f->Int(&schema) && f->String(&topic) && f->String(&encoding) &&
          f->Sized<std::uint32_t>(&metadata))) {
      return Status::Error("Channel is cut short");
    }
    if (channels_.count(id) != 0) return Status::Ok();  // the summary repeats the channels
    const auto type = schemas_.find(schema);
    if (schema != 0 && type == schemas_.end()) {
      return Status::Error("channel " + std::to_string(id) + " (" + topic + ") names schema " +
                           std::to_string(schema) + ", not defined before it");
    }
    channels_[id] = topics_.size();
    topics_.push_back({topic, schema == 0 ? "" : type->second, encoding});
    return Status::Ok();
  }

  Status ReadMessage(Fields* f, BagMessage* message) {
    std::uint16_t channel = 0;
    std::uint32_t sequence = 0;
    std::uint64_t log_time = 0, publish_time = 0;
    if (!(f->Int(&channel) && f->Int(&sequence) && f->Int(&log_time) && f->Int(&publish_time))) {
      return Status::Error("Message is cut short");
    }
    const auto topic = channels_.find(channel);
    if (topic == channels_.end()) {
      return Status::Error("message on channel " + std::to_string(channel) +
                           ", not defined before it");
    }
    message->topic = topic->second;
    message->log_time_ns = static_cast<std::int64_t>(log_time);
    message->data = f->rest();
    ++messages_;
    return Status::Ok();
  }

  Status OpenChunk(Fields* f) {
    std::uint64_t start = 0, end = 0, size = 0;
    std::uint32_t crc = 0;
    std::string compression;
    ros2::ByteView records;
    if (!(f->Int(&start) && f->Int(&end) && f->Int(&size) && f->Int(&crc) &&
          f->String(&compression) && f->Sized<std::uint64_t>(&records))) {
      return RecordError("Chunk is cut short");
    }
    if (Status s = Decompress(compression, records, size, &chunk_); !s.ok()) {
      return RecordError(s.message());
    }
    if (crc != 0 && Crc32(chunk_.data(), chunk_.size()) != crc) {
      return RecordError("CRC mismatch of the uncompressed records");
    }
    in_chunk_ = true;
    chunk_pos_ = 0;
    chunk_record_ = 0;
    return Status::Ok();
  }

  // The next Message in the open chunk (Schema and Channel records on the way are taken in).
  Status NextInChunk(BagMessage* message, bool* found) {
    while (chunk_pos_ < chunk_.size()) {
      const std::size_t at = chunk_pos_;
      ++chunk_record_;
      auto error = [&](const std::string& what) {
        return RecordError("its record " + std::to_string(chunk_record_) + " at chunk offset " +
                           std::to_string(at) + ": " + what);
      };
      if (chunk_.size() - at < kRecordHeaderBytes) return error("record header cut short");
      const std::uint8_t op = chunk_[at];
      std::uint64_t length = 0;
      std::memcpy(&length, &chunk_[at + 1], 8);
      if (length > chunk_.size() - at - kRecordHeaderBytes) {
        return error("content of " + std::to_string(length) + " bytes runs past the chunk's end");
      }
      chunk_pos_ = at + kRecordHeaderBytes + static_cast<std::size_t>(length);
      Fields f(&chunk_[at + kRecordHeaderBytes], static_cast<std::size_t>(length));
      Status s = op == kSchema    ? ReadSchema(&f)
                 : op == kChannel ? ReadChannel(&f)
                 : op == kMessage ? ReadMessage(&f, message)
                                  : Status::Ok();
      if (!s.ok()) return error(s.message());
      if (op == kMessage) {
        *found = true;
        return Status::Ok();
      }
    }
    return Status::Ok();
  }

  Status CheckAttachment(ros2::ByteView content) {
    Fields f(content.data, content.size);
    std::uint64_t log_time = 0, create_time = 0;
    std::string name, media_type;
    ros2::ByteView data;
    std::uint32_t crc = 0;
    if (!(f.Int(&log_time) && f.Int(&create_time) && f.String(&name) && f.String(&media_type) &&
          f.Sized<std::uint64_t>(&data))) {
      return RecordError("Attachment is cut short");
    }
    const std::size_t crc_at = f.pos();
    if (!f.Int(&crc)) return RecordError("Attachment is cut short");
    if (crc != 0 && Crc32(content.data, crc_at) != crc) {
      return RecordError("CRC mismatch of attachment '" + name + "'");
    }
    return Status::Ok();
  }

  Status CheckFooter(Fields* f, const std::uint8_t* head) {
    std::uint64_t summary_start = 0, summary_offset_start = 0;
    std::uint32_t crc = 0;
    if (!(f->Int(&summary_start) && f->Int(&summary_offset_start) && f->Int(&crc))) {
      return RecordError("Footer is cut short");
    }
    if (crc != 0 && summary_start != 0 && summary_start == summary_start_) {
      std::uint32_t summary = Crc32(head, kRecordHeaderBytes, summary_crc_);
      summary = Crc32(content_.data(), 16, summary);
      if (summary != crc) return RecordError("summary CRC mismatch");
    }
    std::uint8_t magic[8];
    if (std::fread(magic, 1, 8, file_) != 8 || std::memcmp(magic, kMagic, 8) != 0) {
      return RecordError("no MCAP magic after the Footer (truncated)");
    }
    done_ = true;
    return Status::Ok();
  }

  std::string path_;
  std::FILE* file_ = nullptr;
  std::uint64_t file_size_ = 0, offset_ = 0;  // offset_: the next record's first byte
  // Top-level records numbered from 0 (the Header), as fusion-replay numbers its records.
  std::uint64_t next_record_ = 0, record_ = 0, record_offset_ = 0, messages_ = 0;
  std::uint8_t op_ = 0;  // the current top-level record's opcode
  std::vector<std::uint8_t> content_, chunk_;
  bool in_chunk_ = false, after_data_end_ = false, done_ = false;
  std::size_t chunk_pos_ = 0;
  std::uint64_t chunk_record_ = 0;
  std::uint32_t data_crc_ = 0, expected_data_crc_ = 0, summary_crc_ = 0;
  std::uint64_t summary_start_ = 0;
  std::unordered_map<std::uint16_t, std::string> schemas_;
  std::unordered_map<std::uint16_t, std::size_t> channels_;
  std::vector<BagTopic> topics_;
};

}  // namespace

Status OpenMcapStorage(const std::string& path, std::unique_ptr<BagStorage>* storage) {
  auto mcap = std::make_unique<McapStorage>();
  if (Status s = mcap->Open(path); !s.ok()) return s;
  *storage = std::move(mcap);
  return Status::Ok();
}

}  // namespace fusion::clients
