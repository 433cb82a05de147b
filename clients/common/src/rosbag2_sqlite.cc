// rosbag2's sqlite3 storage (.db3): topics(id, name, type, serialization_format, ...) and
// messages(id, topic_id, timestamp, data), read in the order they were written (by id).
#include <sqlite3.h>

#include <fstream>
#include <unordered_map>

#include "fusion/clients/rosbag2.h"

namespace fusion::clients {
namespace {

class SqliteStorage final : public BagStorage {
 public:
  ~SqliteStorage() override {
    sqlite3_finalize(messages_);
    sqlite3_close(db_);
  }

  Status Open(const std::string& path) {
    path_ = path;
    missing_bytes_ = MissingBytes(path);
    if (sqlite3_open_v2(path.c_str(), &db_, SQLITE_OPEN_READONLY, nullptr) != SQLITE_OK) {
      return Error("cannot open");
    }
    sqlite3_stmt* topics = nullptr;
    if (sqlite3_prepare_v2(db_, "SELECT id, name, type, serialization_format FROM topics", -1,
                           &topics, nullptr) != SQLITE_OK) {
      return Error("no rosbag2 topics table");
    }
    int rc;
    while ((rc = sqlite3_step(topics)) == SQLITE_ROW) {
      index_of_id_[sqlite3_column_int64(topics, 0)] = topics_.size();
      topics_.push_back({Text(topics, 1), Text(topics, 2), Text(topics, 3)});
    }
    sqlite3_finalize(topics);
    if (rc != SQLITE_DONE) return Error("reading the topics");
    if (sqlite3_prepare_v2(db_, "SELECT topic_id, timestamp, data FROM messages ORDER BY id", -1,
                           &messages_, nullptr) != SQLITE_OK) {
      return Error("no rosbag2 messages table");
    }
    return Status::Ok();
  }

  const std::vector<BagTopic>& topics() const override { return topics_; }

  Status Next(BagMessage* message, bool* end) override {
    *end = false;
    const int rc = sqlite3_step(messages_);
    if (rc == SQLITE_DONE) {
      *end = true;
      if (missing_bytes_ == 0) return Status::Ok();
      // sqlite reads a missing page as zeros: the rows it held are simply not there.
      return Status::Error(path_ + ": truncated: the file lacks the last " +
                           std::to_string(missing_bytes_) + " bytes its header announces; " +
                           "messages after message " + std::to_string(count_) + " may be lost");
    }
    if (rc != SQLITE_ROW) return Error("message " + std::to_string(count_ + 1));
    ++count_;
    const auto topic = index_of_id_.find(sqlite3_column_int64(messages_, 0));
    if (topic == index_of_id_.end()) {
      return Status::Error(path_ + ": message " + std::to_string(count_) + " has topic_id " +
                           std::to_string(sqlite3_column_int64(messages_, 0)) +
                           ", not in the topics table");
    }
    message->topic = topic->second;
    message->log_time_ns = sqlite3_column_int64(messages_, 1);
    const void* blob = sqlite3_column_blob(messages_, 2);  // before _bytes (sqlite's rule)
    message->data = ros2::ByteView(static_cast<const std::uint8_t*>(blob),
                                   static_cast<std::size_t>(sqlite3_column_bytes(messages_, 2)));
    return Status::Ok();
  }

 private:
  // Bytes the database header says the file has beyond its size (0 when it has them all, or
  // when the header's page count is not valid: sqlite's own rule, offsets 24 and 92).
  static std::uint64_t MissingBytes(const std::string& path) {
    std::ifstream in(path, std::ios::binary | std::ios::ate);
    const auto size = static_cast<std::uint64_t>(in.tellg());
    unsigned char h[100] = {};
    in.seekg(0);
    if (!in.read(reinterpret_cast<char*>(h), sizeof h)) return 0;
    auto be32 = [&](int at) {
      return std::uint32_t{h[at]} << 24 | std::uint32_t{h[at + 1]} << 16 |
             std::uint32_t{h[at + 2]} << 8 | h[at + 3];
    };
    std::uint64_t page_size = std::uint64_t{h[16]} << 8 | h[17];
    if (page_size == 1) page_size = 65536;
    if (be32(24) != be32(92)) return 0;
    const std::uint64_t announced = page_size * be32(28);
    return announced > size ? announced - size : 0;
  }

  static std::string Text(sqlite3_stmt* statement, int column) {
    const unsigned char* text = sqlite3_column_text(statement, column);
    return text != nullptr ? reinterpret_cast<const char*>(text) : "";
  }

  Status Error(const std::string& what) const {
    return Status::Error(path_ + ": sqlite3: " + what + ": " +
                         (db_ != nullptr ? sqlite3_errmsg(db_) : "out of memory"));
  }

  std::string path_;
  sqlite3* db_ = nullptr;
  sqlite3_stmt* messages_ = nullptr;
  std::vector<BagTopic> topics_;
  std::unordered_map<sqlite3_int64, std::size_t> index_of_id_;
  std::uint64_t count_ = 0;  // messages returned
  std::uint64_t missing_bytes_ = 0;
};

}  // namespace

Status OpenSqliteStorage(const std::string& path, std::unique_ptr<BagStorage>* storage) {
  auto sqlite = std::make_unique<SqliteStorage>();
  if (Status s = sqlite->Open(path); !s.ok()) return s;
  *storage = std::move(sqlite);
  return Status::Ok();
}

}  // namespace fusion::clients
