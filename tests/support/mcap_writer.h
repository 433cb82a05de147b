// A minimal MCAP writer (https://mcap.dev/spec) for tests: magic, Header, Schema, Channel,
// Message records at the top level or in chunks (compression "", "zstd", "lz4" frame), each
// chunk followed by its MessageIndex records, Attachment and Metadata records, DataEnd with the
// data section's CRC, a summary (schemas, channels, Statistics, ChunkIndex, SummaryOffset) and
// the Footer with the summary's CRC. It remembers where every top-level record starts, so that
// tests can cut or damage a file at a chosen record.
#pragma once

#include <lz4frame.h>
#include <zstd.h>

#include <cstdint>
#include <cstring>
#include <map>
#include <stdexcept>
#include <string>
#include <vector>

#include "fusion/clients/crc32.h"

namespace fusion::test {

class McapWriter {
 public:
  struct RecordStart {
    std::uint8_t opcode;
    std::uint64_t offset;  // byte of the opcode
  };

  explicit McapWriter(const std::string& profile = "ros2") {
    out_.assign("\x89MCAP0\r\n", 8);
    std::string header;
    Str(&header, profile);
    Str(&header, "fusion test writer");
    Record(&out_, 0x01, header);
  }

  std::uint16_t AddSchema(const std::string& name, const std::string& encoding = "ros2msg",
                          const std::string& data = "") {
    const auto id = static_cast<std::uint16_t>(schemas_.size() + 1);
    std::string r;
    Int<std::uint16_t>(&r, id);
    Str(&r, name);
    Str(&r, encoding);
    Str(&r, data);
    schemas_.push_back(r);
    Emit(0x03, r);
    return id;
  }

  std::uint16_t AddChannel(std::uint16_t schema, const std::string& topic,
                           const std::string& encoding = "cdr") {
    const auto id = static_cast<std::uint16_t>(channels_.size());
    std::string r;
    Int<std::uint16_t>(&r, id);
    Int<std::uint16_t>(&r, schema);
    Str(&r, topic);
    Str(&r, encoding);
    std::string metadata;  // map<string, string>: offered_qos_profiles as rosbag2 writes it
    Str(&metadata, "offered_qos_profiles");
    Str(&metadata, "");
    Str(&r, metadata);
    channels_.push_back(r);
    Emit(0x04, r);
    return id;
  }

  void AddMessage(std::uint16_t channel, std::uint64_t log_time_ns,
                  const std::vector<std::uint8_t>& data) {
    std::string r;
    Int<std::uint16_t>(&r, channel);
    Int<std::uint32_t>(&r, sequence_++);
    Int<std::uint64_t>(&r, log_time_ns);
    Int<std::uint64_t>(&r, log_time_ns);
    r.append(reinterpret_cast<const char*>(data.data()), data.size());
    if (in_chunk_) {
      chunk_index_[channel].emplace_back(log_time_ns, chunk_.size());
      chunk_start_ns_ = std::min(chunk_start_ns_, log_time_ns);
      chunk_end_ns_ = std::max(chunk_end_ns_, log_time_ns);
    }
    ++messages_;
    Emit(0x05, r);
  }

  // Records until EndChunk() go into one chunk compressed with `compression`.
  void BeginChunk(const std::string& compression) {
    in_chunk_ = true;
    compression_ = compression;
    chunk_.clear();
    chunk_index_.clear();
    chunk_start_ns_ = UINT64_MAX;
    chunk_end_ns_ = 0;
  }

  void EndChunk() {
    in_chunk_ = false;
    const std::string compressed = Compress(chunk_);
    std::string r;
    Int<std::uint64_t>(&r, chunk_start_ns_);
    Int<std::uint64_t>(&r, chunk_end_ns_);
    Int<std::uint64_t>(&r, chunk_.size());
    Int<std::uint32_t>(&r, clients::Crc32(chunk_.data(), chunk_.size()));
    Str(&r, compression_);
    Int<std::uint64_t>(&r, compressed.size());
    r += compressed;
    const std::uint64_t chunk_offset = out_.size();
    Record(&out_, 0x06, r);
    const std::uint64_t index_offset = out_.size();
    std::map<std::uint16_t, std::uint64_t> index_offsets;
    for (const auto& [channel, entries] : chunk_index_) {
      index_offsets[channel] = out_.size();
      std::string index;
      Int<std::uint16_t>(&index, channel);
      Int<std::uint32_t>(&index, static_cast<std::uint32_t>(16 * entries.size()));
      for (const auto& [time, offset] : entries) {
        Int<std::uint64_t>(&index, time);
        Int<std::uint64_t>(&index, offset);
      }
      Record(&out_, 0x07, index);
    }
    std::string ci;  // ChunkIndex, for the summary
    Int<std::uint64_t>(&ci, chunk_start_ns_);
    Int<std::uint64_t>(&ci, chunk_end_ns_);
    Int<std::uint64_t>(&ci, chunk_offset);
    Int<std::uint64_t>(&ci, index_offset - chunk_offset);
    std::string offsets;
    for (const auto& [channel, offset] : index_offsets) {
      Int<std::uint16_t>(&offsets, channel);
      Int<std::uint64_t>(&offsets, offset);
    }
    Str(&ci, offsets);
    Int<std::uint64_t>(&ci, out_.size() - index_offset);
    Str(&ci, compression_);
    Int<std::uint64_t>(&ci, compressed.size());
    Int<std::uint64_t>(&ci, chunk_.size());
    chunk_indexes_.push_back(ci);
    ++chunk_count_;
  }

  void AddAttachment(const std::string& name, const std::string& data) {
    std::string r;
    Int<std::uint64_t>(&r, 1);
    Int<std::uint64_t>(&r, 2);
    Str(&r, name);
    Str(&r, "application/octet-stream");
    Int<std::uint64_t>(&r, data.size());
    r += data;
    Int<std::uint32_t>(&r, clients::Crc32(r.data(), r.size()));
    Record(&out_, 0x09, r);
  }

  void AddMetadata(const std::string& name, const std::string& key, const std::string& value) {
    std::string r, map;
    Str(&r, name);
    Str(&map, key);
    Str(&map, value);
    Str(&r, map);
    Record(&out_, 0x0C, r);
  }

  // DataEnd, the summary, the Footer and the closing magic; the whole file.
  std::string Finish() {
    std::string data_end;
    Int<std::uint32_t>(&data_end, clients::Crc32(out_.data(), out_.size()));
    Record(&out_, 0x0F, data_end);
    const std::uint64_t summary_start = out_.size();
    std::vector<std::pair<std::uint8_t, std::uint64_t>> groups;
    auto group = [&](std::uint8_t op, const std::vector<std::string>& records) {
      if (records.empty()) return;
      groups.emplace_back(op, out_.size());
      for (const auto& r : records) Record(&out_, op, r);
    };
    group(0x03, schemas_);
    group(0x04, channels_);
    std::string stats;
    Int<std::uint64_t>(&stats, messages_);
    Int<std::uint16_t>(&stats, static_cast<std::uint16_t>(schemas_.size()));
    Int<std::uint32_t>(&stats, static_cast<std::uint32_t>(channels_.size()));
    Int<std::uint32_t>(&stats, 1);  // attachments
    Int<std::uint32_t>(&stats, 1);  // metadata
    Int<std::uint32_t>(&stats, chunk_count_);
    Int<std::uint64_t>(&stats, 0);
    Int<std::uint64_t>(&stats, 0);
    Int<std::uint32_t>(&stats, 0);  // empty channel_message_counts map
    group(0x0B, {stats});
    group(0x08, chunk_indexes_);
    const std::uint64_t offsets_start = out_.size();
    for (std::size_t i = 0; i < groups.size(); ++i) {
      const std::uint64_t end = i + 1 < groups.size() ? groups[i + 1].second : offsets_start;
      std::string so;
      so.push_back(static_cast<char>(groups[i].first));
      Int<std::uint64_t>(&so, groups[i].second);
      Int<std::uint64_t>(&so, end - groups[i].second);
      Record(&out_, 0x0E, so);
    }
    std::string footer;
    Int<std::uint64_t>(&footer, summary_start);
    Int<std::uint64_t>(&footer, offsets_start);
    std::string with_head = out_.substr(summary_start);
    with_head.push_back(0x02);
    Int<std::uint64_t>(&with_head, 20);
    with_head += footer;
    Int<std::uint32_t>(&footer, clients::Crc32(with_head.data(), with_head.size()));
    Record(&out_, 0x02, footer);
    out_.append("\x89MCAP0\r\n", 8);
    return out_;
  }

  [[nodiscard]] const std::vector<RecordStart>& records() const { return records_; }

 private:
  template <class T>
  static void Int(std::string* out, T value) {
    out->append(reinterpret_cast<const char*>(&value), sizeof value);  // little-endian host
  }
  static void Str(std::string* out, const std::string& s) {
    Int<std::uint32_t>(out, static_cast<std::uint32_t>(s.size()));
    *out += s;
  }
  void Record(std::string* out, std::uint8_t op, const std::string& content) {
    if (out == &out_) records_.push_back({op, out_.size()});
    out->push_back(static_cast<char>(op));
    Int<std::uint64_t>(out, content.size());
    *out += content;
  }
  void Emit(std::uint8_t op, const std::string& content) {
    if (in_chunk_) {
      chunk_.push_back(static_cast<char>(op));
      Int<std::uint64_t>(&chunk_, content.size());
      chunk_ += content;
    } else {
      Record(&out_, op, content);
    }
  }
  std::string Compress(const std::string& raw) const {
    if (compression_.empty()) return raw;
    std::string out;
    if (compression_ == "zstd") {
      out.resize(ZSTD_compressBound(raw.size()));
      const std::size_t n = ZSTD_compress(out.data(), out.size(), raw.data(), raw.size(), 3);
      if (ZSTD_isError(n)) throw std::runtime_error("zstd");
      out.resize(n);
    } else if (compression_ == "lz4") {
      out.resize(LZ4F_compressFrameBound(raw.size(), nullptr));
      const std::size_t n =
          LZ4F_compressFrame(out.data(), out.size(), raw.data(), raw.size(), nullptr);
      if (LZ4F_isError(n)) throw std::runtime_error("lz4");
      out.resize(n);
    } else {
      throw std::invalid_argument("compression " + compression_);
    }
    return out;
  }

  std::string out_, chunk_, compression_;
  bool in_chunk_ = false;
  std::uint32_t sequence_ = 0, chunk_count_ = 0;
  std::uint64_t messages_ = 0, chunk_start_ns_ = 0, chunk_end_ns_ = 0;
  std::vector<std::string> schemas_, channels_, chunk_indexes_;
  std::map<std::uint16_t, std::vector<std::pair<std::uint64_t, std::uint64_t>>> chunk_index_;
  std::vector<RecordStart> records_;
};

}  // namespace fusion::test
