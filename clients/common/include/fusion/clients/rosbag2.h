// ROS 2 bags (rosbag2) to fusion recordings: `fusion-import rosbag2 BAG`.
//
// A bag is a directory (metadata.yaml and its storage files) or a single storage file: sqlite3
// (.db3: tables topics(id, name, type, serialization_format, offered_qos_profiles) and
// messages(id, topic_id, timestamp, data)) or MCAP (.mcap, read sequentially; chunks compressed
// with zstd or lz4 or not at all; CRCs checked where the file has them). Messages are CDR
// (ros2/cdr.h); clouds come from a sensor_msgs/msg/PointCloud2 topic or a depth
// sensor_msgs/msg/Image topic with its sensor_msgs/msg/CameraInfo, converted by ros2/points.h.
// Each cloud's pose is the tf chain from its header.frame_id to the map frame at its
// header.stamp, interpolated, from every /tf and /tf_static message of the bag (read first, so
// that transforms recorded after a cloud are found too).
#pragma once

#include <cstdint>
#include <cstdio>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "fusion/clients/importers.h"
#include "fusion/core/status.h"
#include "fusion/ros2/messages.h"

namespace fusion::clients {

// A topic of a bag: name, ROS type ("sensor_msgs/msg/PointCloud2"), serialization ("cdr").
struct BagTopic {
  std::string name, type, serialization_format;
};

// One message as stored: its topic (index into BagStorage::topics()), the time the recorder
// received it and the serialized bytes (valid until the next BagStorage::Next).
struct BagMessage {
  std::size_t topic = 0;
  std::int64_t log_time_ns = 0;
  ros2::ByteView data;
};

// One storage file of a bag, read front to back.
class BagStorage {
 public:
  virtual ~BagStorage() = default;
  // The topics met so far (sqlite3: all of them from the start; MCAP: the channels read so far).
  [[nodiscard]] virtual const std::vector<BagTopic>& topics() const = 0;
  // The next message, or *end = true after the last. An error says where the file breaks
  // (MCAP: record number, its byte offset and the message count; sqlite3: the message number);
  // every message before it has been returned.
  virtual Status Next(BagMessage* message, bool* end) = 0;
};

// By the file's first bytes: "SQLite format 3" or the MCAP magic; anything else is an
// "unknown storage" error.
Status OpenBagStorage(const std::string& path, std::unique_ptr<BagStorage>* storage);
Status OpenSqliteStorage(const std::string& path, std::unique_ptr<BagStorage>* storage);
Status OpenMcapStorage(const std::string& path, std::unique_ptr<BagStorage>* storage);

// The storage files of a bag in reading order: the path itself for a file; for a directory the
// relative_file_paths of its metadata.yaml (storage_identifier sqlite3 or mcap; compressed bags
// are refused), or without metadata.yaml its *.db3 and *.mcap files by name.
Status FindBagFiles(const std::string& path, std::vector<std::string>* files);

struct Rosbag2Options {
  std::string bag;                // directory, .db3 or .mcap
  std::string points_topic;       // sensor_msgs/msg/PointCloud2; or:
  std::string depth_topic;        // sensor_msgs/msg/Image (16UC1 mm, 32FC1 m) with
  std::string camera_info_topic;  // sensor_msgs/msg/CameraInfo (same stamp, else the nearest)
  int stride = 1;                 // depth: every stride-th pixel in both directions
  std::string map_frame = "map";  // the recording's world frame
  std::string tf_topic = "/tf", tf_static_topic = "/tf_static";
  // The frame convention of the cloud messages' points (depth images: always optical).
  PointFrame frame = PointFrame::kOptical;
  std::string sensor_id = "ros2";
  std::size_t max_points = std::size_t{1} << 24;  // larger clouds are skipped (too_large)
  std::FILE* progress = nullptr;  // progress, skips and notes (fusion-import: stderr)
};

// What an import did. Skips are counted by reason: a Ros2RejectName, a TransformStatusName,
// "no_camera_info" or "cdr" (a message that does not decode).
struct Rosbag2Report {
  std::uint64_t messages = 0;                     // read in the clouds' pass
  std::uint64_t cloud_messages = 0;               // on the points (or depth) topic
  std::uint64_t clouds_imported = 0;              // handed to the sink
  std::uint64_t transforms = 0;                   // tf samples in the buffer
  std::map<std::string, std::uint64_t> skipped;   // by reason
  std::map<std::string, std::string> first_skip;  // reason -> the first case, in words
};

// Imports the clouds into `sink` in bag order, numbered from 1, stamped with their
// header.stamp (receive time = the bag's log time). Errors: a bad option or path, unknown
// storage, a topic missing (the message lists the bag's topics and types) or of another type,
// a serialization other than cdr, no cloud with a pose; a truncated or corrupt storage file
// after the clouds before the break went to the sink (the error says where it breaks), also
// messages that do not decode (they are skipped, the others imported).
Status ImportRosbag2(const Rosbag2Options& options, const CloudSink& sink,
                     Rosbag2Report* report = nullptr);

// fusion-import rosbag2 --help (without the common options).
extern const char* const kRosbag2Usage;
// An option of `fusion-import rosbag2` with its value; false if `flag` is none of them.
bool ApplyRosbag2Option(const std::string& flag, const std::string& value, Rosbag2Options* options,
                        Status* status);
// After parsing: --points-topic or (--depth-topic and --camera-info-topic), not both.
Status CheckRosbag2Options(const Rosbag2Options& options);

}  // namespace fusion::clients
