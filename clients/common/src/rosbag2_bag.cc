// A rosbag2 bag's files (metadata.yaml or the directory's storage files), the storage of one
// file by its magic bytes, and the options of `fusion-import rosbag2`.
#include <algorithm>
#include <cstring>
#include <filesystem>
#include <fstream>

#include "fusion/clients/cli.h"
#include "fusion/clients/rosbag2.h"

namespace fusion::clients {
namespace {

namespace fs = std::filesystem;

std::string Trim(const std::string& s) {
  const auto first = s.find_first_not_of(" \t\r");
  if (first == std::string::npos) return "";
  return s.substr(first, s.find_last_not_of(" \t\r") - first + 1);
}
std::string Unquote(const std::string& s) {
  const std::string t = Trim(s);
  if (t.size() >= 2 && (t.front() == '\'' || t.front() == '"') && t.back() == t.front()) {
    return t.substr(1, t.size() - 2);
  }
  return t;
}

// What fusion-import needs of rosbag2's metadata.yaml (rosbag2_bagfile_information).
struct BagMetadata {
  std::string storage_identifier, compression_format;
  std::vector<std::string> relative_file_paths;
};

// A line-based reading of the keys above (the file is YAML written by rosbag2, not any YAML).
Status ReadMetadata(const std::string& path, BagMetadata* metadata) {
  std::ifstream in(path);
  if (!in) return Status::Error(path + ": cannot open");
  bool in_paths = false;
  for (std::string line; std::getline(in, line);) {
    const std::string t = Trim(line);
    if (in_paths && t.rfind("- ", 0) == 0) {
      metadata->relative_file_paths.push_back(Unquote(t.substr(2)));
      continue;
    }
    in_paths = false;
    const auto colon = t.find(':');
    if (colon == std::string::npos) continue;
    const std::string key = t.substr(0, colon), value = Unquote(t.substr(colon + 1));
    if (key == "storage_identifier") metadata->storage_identifier = value;
    if (key == "compression_format") metadata->compression_format = value;
    if (key == "relative_file_paths") in_paths = true;
  }
  return Status::Ok();
}

bool IsStorageFile(const fs::path& p) {
  return p.extension() == ".db3" || p.extension() == ".mcap";
}

}  // namespace

Status FindBagFiles(const std::string& path, std::vector<std::string>* files) {
  files->clear();
  std::error_code ec;
  if (!fs::is_directory(path, ec)) {
    if (!fs::exists(path, ec)) return Status::Error(path + ": no such bag (file or directory)");
    files->push_back(path);
    return Status::Ok();
  }
  const fs::path metadata_path = fs::path(path) / "metadata.yaml";
  if (fs::exists(metadata_path, ec)) {
    BagMetadata metadata;
    if (Status s = ReadMetadata(metadata_path.string(), &metadata); !s.ok()) return s;
    if (!metadata.compression_format.empty()) {
      return Status::Error(metadata_path.string() + ": compression_format " +
                           metadata.compression_format +
                           " is not supported: decompress the bag first (ros2 bag convert)");
    }
    if (metadata.storage_identifier != "sqlite3" && metadata.storage_identifier != "mcap") {
      return Status::Error(metadata_path.string() + ": unknown storage '" +
                           metadata.storage_identifier + "' (sqlite3 and mcap are supported)");
    }
    for (const std::string& file : metadata.relative_file_paths) {
      files->push_back((fs::path(path) / file).string());
    }
  } else {
    for (const auto& entry : fs::directory_iterator(path, ec)) {
      if (entry.is_regular_file() && IsStorageFile(entry.path())) {
        files->push_back(entry.path().string());
      }
    }
    // bag_2 before bag_10.
    std::sort(files->begin(), files->end(), [](const std::string& a, const std::string& b) {
      return a.size() != b.size() ? a.size() < b.size() : a < b;
    });
  }
  if (files->empty()) {
    return Status::Error(path + ": no storage files (metadata.yaml, *.db3 or *.mcap)");
  }
  return Status::Ok();
}

Status OpenBagStorage(const std::string& path, std::unique_ptr<BagStorage>* storage) {
  char head[16] = {};
  std::ifstream in(path, std::ios::binary);
  if (!in) return Status::Error(path + ": cannot open: " + std::strerror(errno));
  in.read(head, sizeof head);
  if (in.gcount() == 16 && std::memcmp(head, "SQLite format 3", 16) == 0) {
    return OpenSqliteStorage(path, storage);
  }
  if (in.gcount() >= 8 && std::memcmp(head, "\x89MCAP0\r\n", 8) == 0) {
    return OpenMcapStorage(path, storage);
  }
  const std::string extension = fs::path(path).extension().string();
  return Status::Error(path + ": unknown storage: neither sqlite3 nor MCAP" +
                       (extension == ".zstd" || extension == ".lz4"
                            ? std::string(" (a compressed bag file: decompress it first)")
                            : std::string()));
}

const char* const kRosbag2Usage =
    R"(fusion-import rosbag2 BAG -o OUT.frec (--points-topic T | --depth-topic T --camera-info-topic T) [options]

BAG: a rosbag2 directory (metadata.yaml and its files) or one .db3 (sqlite3) or .mcap file
(chunks uncompressed, zstd or lz4). Messages must be CDR. Every cloud is posed by the tf chain
from its header.frame_id to the map frame at its header.stamp, interpolated, from all the
bag's /tf and /tf_static messages; clouds without a pose are skipped (counted by reason).
  --points-topic T        sensor_msgs/msg/PointCloud2 (FLOAT32 x y z; organized or not)
  --depth-topic T         sensor_msgs/msg/Image, 16UC1 (mm) or 32FC1 (m), with
  --camera-info-topic T   its sensor_msgs/msg/CameraInfo (K; the one of the same stamp)
  --stride N              depth: keep every N-th pixel in both directions (default 1)
  --map-frame F           the recording's world frame (default map)
  --tf-topic T            default /tf
  --tf-static-topic T     default /tf_static
  --frame optical|body    the convention of the PointCloud2 frames (default optical: x right,
                          y down, z forward; body = REP-103 x forward, y left, z up, turned
                          into the optical frame as `scan --help` says); depth: always optical
  --max-points N          skip clouds with more points (default 16777216)
A bag that breaks (truncated, corrupt) keeps the clouds before the break; the error names the
record and byte offset (MCAP) or message number (sqlite3), and the exit code is 1.
--print-sensor: as for pcd.
)";

bool ApplyRosbag2Option(const std::string& flag, const std::string& value, Rosbag2Options* options,
                        Status* status) {
  std::string* const text = flag == "--points-topic"        ? &options->points_topic
                            : flag == "--depth-topic"       ? &options->depth_topic
                            : flag == "--camera-info-topic" ? &options->camera_info_topic
                            : flag == "--map-frame"         ? &options->map_frame
                            : flag == "--tf-topic"          ? &options->tf_topic
                            : flag == "--tf-static-topic"   ? &options->tf_static_topic
                                                            : nullptr;
  if (text != nullptr) {
    *text = value;
    if (value.empty()) *status = Status::Error(flag + " must not be empty");
    return true;
  }
  std::uint64_t n = 0;
  if (flag == "--stride") {
    *status = ParseUint(flag, value, &n);
    if (status->ok() && (n == 0 || n > 4096)) *status = Status::Error("--stride must be 1..4096");
    options->stride = static_cast<int>(n);
    return true;
  }
  if (flag == "--max-points") {
    *status = ParseUint(flag, value, &n);
    if (status->ok() && n == 0) *status = Status::Error("--max-points must be at least 1");
    options->max_points = static_cast<std::size_t>(n);
    return true;
  }
  if (flag == "--frame") {
    *status = ParsePointFrame(flag, value, &options->frame);
    return true;
  }
  return false;
}

Status CheckRosbag2Options(const Rosbag2Options& o) {
  const bool points = !o.points_topic.empty(), depth = !o.depth_topic.empty();
  if (points && (depth || !o.camera_info_topic.empty())) {
    return Status::Error("--points-topic or --depth-topic, not both");
  }
  if (!points && !depth) return Status::Error("needs --points-topic or --depth-topic");
  if (depth && o.camera_info_topic.empty()) {
    return Status::Error("--depth-topic needs --camera-info-topic");
  }
  if (o.stride < 1) return Status::Error("--stride must be at least 1");
  if (o.bag.empty()) return Status::Error("missing BAG");
  return Status::Ok();
}

}  // namespace fusion::clients
