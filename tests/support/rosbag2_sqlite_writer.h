// A rosbag2 sqlite3 storage file (.db3) with the tables rosbag2 creates, and the bag
// directory's metadata.yaml, for tests.
#pragma once

#include <sqlite3.h>

#include <cstdint>
#include <fstream>
#include <stdexcept>
#include <string>
#include <vector>

namespace fusion::test {

class Rosbag2SqliteWriter {
 public:
  explicit Rosbag2SqliteWriter(const std::string& path) {
    std::remove(path.c_str());
    if (sqlite3_open(path.c_str(), &db_) != SQLITE_OK) throw std::runtime_error("sqlite open");
    Exec("PRAGMA journal_mode = MEMORY;");
    Exec("CREATE TABLE schema(schema_version INTEGER PRIMARY KEY, ros_distro TEXT NOT NULL);");
    Exec("INSERT INTO schema VALUES (3, 'humble');");
    Exec(
        "CREATE TABLE topics(id INTEGER PRIMARY KEY, name TEXT NOT NULL, type TEXT NOT NULL, "
        "serialization_format TEXT NOT NULL, offered_qos_profiles TEXT NOT NULL);");
    Exec(
        "CREATE TABLE messages(id INTEGER PRIMARY KEY, topic_id INTEGER NOT NULL, timestamp "
        "INTEGER NOT NULL, data BLOB NOT NULL);");
    Exec("CREATE INDEX timestamp_idx ON messages (timestamp ASC);");
    Exec("BEGIN;");
  }
  ~Rosbag2SqliteWriter() { Close(); }

  int AddTopic(const std::string& name, const std::string& type,
               const std::string& serialization = "cdr") {
    const int id = ++topics_;
    sqlite3_stmt* s = Prepare("INSERT INTO topics VALUES (?, ?, ?, ?, '')");
    sqlite3_bind_int(s, 1, id);
    sqlite3_bind_text(s, 2, name.c_str(), -1, SQLITE_TRANSIENT);
    sqlite3_bind_text(s, 3, type.c_str(), -1, SQLITE_TRANSIENT);
    sqlite3_bind_text(s, 4, serialization.c_str(), -1, SQLITE_TRANSIENT);
    Step(s);
    return id;
  }

  void AddMessage(int topic, std::int64_t timestamp_ns, const std::vector<std::uint8_t>& data) {
    sqlite3_stmt* s = Prepare("INSERT INTO messages (topic_id, timestamp, data) VALUES (?, ?, ?)");
    sqlite3_bind_int(s, 1, topic);
    sqlite3_bind_int64(s, 2, timestamp_ns);
    sqlite3_bind_blob(s, 3, data.data(), static_cast<int>(data.size()), SQLITE_TRANSIENT);
    Step(s);
  }

  void Close() {
    if (db_ == nullptr) return;
    Exec("COMMIT;");
    sqlite3_close(db_);
    db_ = nullptr;
  }

 private:
  void Exec(const char* sql) {
    char* error = nullptr;
    if (sqlite3_exec(db_, sql, nullptr, nullptr, &error) != SQLITE_OK) {
      const std::string what = error != nullptr ? error : "?";
      sqlite3_free(error);
      throw std::runtime_error(what);
    }
  }
  sqlite3_stmt* Prepare(const char* sql) {
    sqlite3_stmt* s = nullptr;
    if (sqlite3_prepare_v2(db_, sql, -1, &s, nullptr) != SQLITE_OK) {
      throw std::runtime_error(sqlite3_errmsg(db_));
    }
    return s;
  }
  void Step(sqlite3_stmt* s) {
    const int rc = sqlite3_step(s);
    sqlite3_finalize(s);
    if (rc != SQLITE_DONE) throw std::runtime_error(sqlite3_errmsg(db_));
  }

  sqlite3* db_ = nullptr;
  int topics_ = 0;
};

// rosbag2's metadata.yaml for a bag of `files` (relative to the directory).
inline void WriteRosbag2Metadata(const std::string& directory, const std::string& storage,
                                 const std::vector<std::string>& files,
                                 const std::string& compression_format = "") {
  std::ofstream out(directory + "/metadata.yaml");
  out << "rosbag2_bagfile_information:\n  version: 5\n  storage_identifier: " << storage
      << "\n  duration:\n    nanoseconds: 3000000000\n  starting_time:\n"
      << "    nanoseconds_since_epoch: 1700000000000000000\n  message_count: 0\n"
      << "  topics_with_message_count: []\n  compression_format: \"" << compression_format
      << "\"\n  compression_mode: \"\"\n  relative_file_paths:\n";
  for (const auto& f : files) out << "    - " << f << "\n";
  out << "  files:\n";
  for (const auto& f : files) out << "    - path: " << f << "\n      message_count: 0\n";
}

}  // namespace fusion::test
