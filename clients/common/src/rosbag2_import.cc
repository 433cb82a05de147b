// fusion-import rosbag2 (fusion/clients/rosbag2.h): two passes over the bag. The first takes in
// every tf and tf_static transform (and the CameraInfo messages), so that a cloud finds
// transforms recorded after it; the second converts the clouds, each posed by the tf chain from
// its frame to the map frame at its stamp.
#include <unistd.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <functional>
#include <limits>

#include "fusion/clients/cli.h"
#include "fusion/clients/rosbag2.h"
#include "fusion/core/transform_buffer.h"
#include "fusion/ros2/cdr.h"
#include "fusion/ros2/points.h"

namespace fusion::clients {
namespace {

constexpr const char* kPointCloud2Type = "sensor_msgs/msg/PointCloud2";
constexpr const char* kImageType = "sensor_msgs/msg/Image";
constexpr const char* kCameraInfoType = "sensor_msgs/msg/CameraInfo";
constexpr const char* kTfType = "tf2_msgs/msg/TFMessage";

// tf2 ignores a leading slash (a ROS 1 habit).
std::string FrameName(const std::string& frame) {
  return !frame.empty() && frame[0] == '/' ? frame.substr(1) : frame;
}

struct TfSample {
  std::string parent, child;
  double stamp_s;
  Eigen::Isometry3d T_parent_child;
  bool is_static;
};

// One message of the bag, as both passes see it.
struct BagItem {
  const BagTopic& topic;
  const BagMessage& message;
  std::uint64_t number;  // 1-based over the whole bag
};
using ItemFn = std::function<Status(const BagItem&)>;

// Every message of every file in order, then `fn` of each; stops at the first storage error
// (after the messages before it) or the first error of `fn`. *topics receives the topics of
// every file opened.
Status ForEachMessage(const std::vector<std::string>& files, const ItemFn& fn,
                      std::vector<BagTopic>* topics) {
  std::uint64_t number = 0;
  for (const std::string& file : files) {
    std::unique_ptr<BagStorage> storage;
    if (Status s = OpenBagStorage(file, &storage); !s.ok()) return s;
    Status status;
    for (bool end = false; status.ok();) {
      BagMessage message;
      status = storage->Next(&message, &end);
      if (!status.ok() || end) break;
      status = fn({storage->topics()[message.topic], message, ++number});
    }
    for (const BagTopic& t : storage->topics()) {
      const bool known = std::any_of(topics->begin(), topics->end(),
                                     [&](const BagTopic& k) { return k.name == t.name; });
      if (!known) topics->push_back(t);
    }
    if (!status.ok()) return status;
  }
  return Status::Ok();
}

Eigen::Isometry3d IsometryOf(const ros2::Transform& t, bool* valid) {
  Eigen::Quaterniond q(t.rotation.w, t.rotation.x, t.rotation.y, t.rotation.z);
  const double norm = q.norm();
  *valid = std::isfinite(norm) && norm > 1e-9 && std::isfinite(t.translation.x) &&
           std::isfinite(t.translation.y) && std::isfinite(t.translation.z);
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  if (!*valid) return T;
  T.linear() = Eigen::Quaterniond(q.coeffs() / norm).toRotationMatrix();
  T.translation() = Eigen::Vector3d(t.translation.x, t.translation.y, t.translation.z);
  return T;
}

fusion::v1::RecordedPose PoseOf(const Eigen::Isometry3d& T) {
  Eigen::Quaterniond q(T.rotation());
  q.normalize();
  fusion::v1::RecordedPose pose;
  pose.set_tx(T.translation().x());
  pose.set_ty(T.translation().y());
  pose.set_tz(T.translation().z());
  pose.set_qx(q.x());
  pose.set_qy(q.y());
  pose.set_qz(q.z());
  pose.set_qw(q.w());
  return pose;
}

class Importer {
 public:
  Importer(const Rosbag2Options& o, const CloudSink& sink, Rosbag2Report* report)
      : o_(o), sink_(sink), report_(*report) {}

  Status Run() {
    if (Status s = CheckRosbag2Options(o_); !s.ok()) return s;
    if (Status s = FindBagFiles(o_.bag, &files_); !s.ok()) return s;
    const Status first = ForEachMessage(
        files_, [this](const BagItem& item) { return Collect(item); }, &topics_);
    // A bag that breaks before its topics are all known: the break is the news.
    if (Status s = CheckTopics(); !s.ok()) return first.ok() ? s : first;
    FillTransformBuffer();
    const Status second = ForEachMessage(
        files_, [this](const BagItem& item) { return Convert(item); }, &topics_);
    EndProgressLine();
    PrintSkips();
    if (!second.ok()) return second;
    if (!first.ok()) return first;  // a break only the first pass met (not expected)
    return Verdict();
  }

 private:
  // A running count on a terminal (one line, rewritten), a line every 10 s in a log.
  void Progress(const char* pass, std::uint64_t messages) {
    const auto now = std::chrono::steady_clock::now();
    if (now < next_progress_) return;
    const bool tty = isatty(fileno(o_.progress)) != 0;
    next_progress_ = now + (tty ? std::chrono::milliseconds(500) : std::chrono::seconds(10));
    std::fprintf(o_.progress, "%sfusion-import: rosbag2: %s: %llu messages, %llu clouds%s",
                 tty ? "\r" : "", pass, static_cast<unsigned long long>(messages),
                 static_cast<unsigned long long>(report_.clouds_imported), tty ? "" : "\n");
    std::fflush(o_.progress);
    progress_line_open_ = tty;
  }

  const std::string& CloudTopic() const {
    return o_.points_topic.empty() ? o_.depth_topic : o_.points_topic;
  }

  // First pass: transforms and camera infos; decode failures of those are noted.
  Status Collect(const BagItem& item) {
    const std::string& name = item.topic.name;
    ++counts_[name];
    if (o_.progress != nullptr && item.number % 64 == 0) Progress("tf", item.number);
    const bool is_static = name == o_.tf_static_topic;
    if (is_static || name == o_.tf_topic) {
      ros2::TFMessage tf;
      const ros2::CdrResult r = ros2::DecodeCdr(item.message.data, &tf);
      if (!r.ok()) return NoteUndecodable(item, r.error);
      for (const ros2::TransformStamped& t : tf.transforms) {
        bool valid = false;
        const Eigen::Isometry3d T = IsometryOf(t.transform, &valid);
        if (!valid) {
          ++invalid_transforms_;
          continue;
        }
        tf_.push_back({FrameName(t.header.frame_id), FrameName(t.child_frame_id),
                       t.header.stamp.seconds(), T, is_static});
      }
    } else if (name == o_.camera_info_topic) {
      ros2::CameraInfo info;
      const ros2::CdrResult r = ros2::DecodeCdr(item.message.data, &info);
      if (!r.ok()) return NoteUndecodable(item, r.error);
      camera_infos_.emplace_back(info.header.stamp.seconds(), info);
    }
    return Status::Ok();
  }

  Status NoteUndecodable(const BagItem& item, const std::string& error) {
    if (undecodable_++ == 0) {
      first_undecodable_ =
          "message " + std::to_string(item.number) + " on " + item.topic.name + ": " + error;
    }
    return Status::Ok();
  }

  std::string TopicList() const {
    std::string list;
    for (const BagTopic& t : topics_) {
      list += "\n  " + t.name + " (" + t.type + ", " + std::to_string(Count(t.name)) + " messages)";
    }
    return list.empty() ? " none" : list;
  }
  std::uint64_t Count(const std::string& topic) const {
    const auto it = counts_.find(topic);
    return it == counts_.end() ? 0 : it->second;
  }

  Status CheckTopic(const std::string& name, const char* type) const {
    for (const BagTopic& t : topics_) {
      if (t.name != name) continue;
      if (t.type != type) {
        return Status::Error("topic " + name + " is " + t.type + ", not " + type);
      }
      if (t.serialization_format != "cdr") {
        return Status::Error("topic " + name + " is serialized as '" + t.serialization_format +
                             "'; only cdr is supported");
      }
      return Status::Ok();
    }
    return Status::Error("topic " + name + " is not in " + o_.bag + "; its topics:" + TopicList());
  }

  Status CheckTopics() const {
    for (const BagTopic& t : topics_) {
      if ((t.name == o_.tf_topic || t.name == o_.tf_static_topic) && t.type != kTfType) {
        return Status::Error("topic " + t.name + " is " + t.type + ", not " + kTfType);
      }
    }
    if (!o_.points_topic.empty()) return CheckTopic(o_.points_topic, kPointCloud2Type);
    if (Status s = CheckTopic(o_.depth_topic, kImageType); !s.ok()) return s;
    return CheckTopic(o_.camera_info_topic, kCameraInfoType);
  }

  // The bag's whole span of transforms, every one kept (the buffer drops none by age or count).
  void FillTransformBuffer() {
    std::stable_sort(tf_.begin(), tf_.end(),
                     [](const TfSample& a, const TfSample& b) { return a.stamp_s < b.stamp_s; });
    double span_s = 1.0;
    if (!tf_.empty()) span_s += tf_.back().stamp_s - tf_.front().stamp_s;
    if (!std::isfinite(span_s)) span_s = std::numeric_limits<double>::max();
    buffer_ = std::make_unique<TransformBuffer>(span_s, tf_.size() + 1);
    for (const TfSample& t : tf_)
      buffer_->Add(t.parent, t.child, t.stamp_s, t.T_parent_child, t.is_static);
    report_.transforms = tf_.size();
    std::sort(camera_infos_.begin(), camera_infos_.end(),
              [](const auto& a, const auto& b) { return a.first < b.first; });
    if (o_.progress != nullptr && tf_.empty()) {
      std::fprintf(o_.progress, "fusion-import: rosbag2: no transforms on %s or %s\n",
                   o_.tf_topic.c_str(), o_.tf_static_topic.c_str());
    }
    if (o_.progress != nullptr && invalid_transforms_ > 0) {
      std::fprintf(o_.progress,
                   "fusion-import: rosbag2: %llu transforms ignored (quaternion zero "
                   "or values not finite)\n",
                   static_cast<unsigned long long>(invalid_transforms_));
    }
  }

  // Second pass: every message on the cloud topic becomes a cloud or a counted skip.
  Status Convert(const BagItem& item) {
    ++report_.messages;
    if (o_.progress != nullptr && report_.messages % 64 == 0) Progress("clouds", report_.messages);
    if (item.topic.name != CloudTopic()) return Status::Ok();
    ++report_.cloud_messages;
    fusion::v1::RecordedCloud cloud;
    ros2::Header header;
    std::string reason, detail;
    if (!Points(item, &cloud, &header, &reason, &detail)) return Skip(item, reason, detail);
    const std::string frame = FrameName(header.frame_id);
    Eigen::Isometry3d T_map_frame;
    const TransformStatus status =
        buffer_->Lookup(o_.map_frame, frame, header.stamp.seconds(), &T_map_frame);
    if (status != TransformStatus::kOk) {
      return Skip(item, TransformStatusName(status),
                  "tf from '" + frame + "' to '" + o_.map_frame + "' at " +
                      std::to_string(header.stamp.seconds()) + " s");
    }
    *cloud.mutable_t_world_sensor() = PoseOf(T_map_frame);
    SetIdentity(o_.sensor_id, report_.clouds_imported + 1, header.stamp.seconds(),
                files_.size() == 1
                    ? files_[0] + " " + item.topic.name + " #" + std::to_string(item.number)
                    : o_.bag + " " + item.topic.name + " #" + std::to_string(item.number),
                &cloud);
    cloud.mutable_stamp()->set_sec(header.stamp.sec);  // exact, not through a double
    cloud.mutable_stamp()->set_nanosec(header.stamp.nanosec);
    cloud.set_receive_time_unix_ns(item.message.log_time_ns);
    if (!o_.points_topic.empty()) ToOpticalFrame(o_.frame, &cloud);
    ++report_.clouds_imported;
    return sink_(std::move(cloud));
  }

  // The cloud's points and shape; false with a reason (and detail) if it has none.
  bool Points(const BagItem& item, fusion::v1::RecordedCloud* cloud, ros2::Header* header,
              std::string* reason, std::string* detail) {
    ros2::Ros2Reject reject;
    if (!o_.points_topic.empty()) {
      ros2::PointCloud2 msg;
      if (const ros2::CdrResult r = ros2::DecodeCdr(item.message.data, &msg); !r.ok()) {
        return Undecodable(item, r.error, reason, detail);
      }
      reject = ros2::PointsFromPointCloud2(msg, o_.max_points, &xyz_, detail);
      cloud->set_width(msg.width);
      cloud->set_height(msg.height);
      *header = msg.header;
    } else {
      ros2::Image image;
      if (const ros2::CdrResult r = ros2::DecodeCdr(item.message.data, &image); !r.ok()) {
        return Undecodable(item, r.error, reason, detail);
      }
      *header = image.header;
      const ros2::CameraInfo* info = CameraInfoFor(image.header.stamp.seconds());
      if (info == nullptr) {
        *reason = "no_camera_info";
        *detail = "no message on " + o_.camera_info_topic;
        return false;
      }
      reject = ros2::PointsFromDepthImage(image, *info, o_.stride, o_.max_points, &xyz_, detail);
      cloud->set_width(ros2::StridedSize(image.width, o_.stride));
      cloud->set_height(ros2::StridedSize(image.height, o_.stride));
    }
    if (reject != ros2::Ros2Reject::kNone) {
      *reason = ros2::Ros2RejectName(reject);
      return false;
    }
    if (xyz_.empty()) {
      *reason = "empty";
      *detail = "no points";
      return false;
    }
    cloud->mutable_xyz_f32le()->assign(reinterpret_cast<const char*>(xyz_.data()),
                                       xyz_.size() * sizeof(float));  // little-endian host
    return true;
  }

  bool Undecodable(const BagItem& item, const std::string& error, std::string* reason,
                   std::string* detail) {
    (void)NoteUndecodable(item, error);
    *reason = "cdr";
    *detail = error;
    return false;
  }

  // The CameraInfo stamped like the image, else the nearest in time; nullptr if none.
  const ros2::CameraInfo* CameraInfoFor(double stamp_s) const {
    if (camera_infos_.empty()) return nullptr;
    auto it = std::lower_bound(camera_infos_.begin(), camera_infos_.end(), stamp_s,
                               [](const auto& a, double s) { return a.first < s; });
    if (it == camera_infos_.end()) return &camera_infos_.back().second;
    if (it != camera_infos_.begin() && stamp_s - std::prev(it)->first < it->first - stamp_s) {
      --it;
    }
    return &it->second;
  }

  Status Skip(const BagItem& item, const std::string& reason, const std::string& detail) {
    if (report_.skipped[reason]++ == 0) {
      const std::string what =
          "message " + std::to_string(item.number) + " (" + item.topic.name + "): " + detail;
      report_.first_skip[reason] = what;
      if (o_.progress != nullptr) {
        EndProgressLine();
        std::fprintf(o_.progress, "fusion-import: rosbag2: skipped a cloud: %s: %s\n",
                     reason.c_str(), what.c_str());
      }
    }
    return Status::Ok();
  }

  // A message after the running count starts on a line of its own.
  void EndProgressLine() {
    if (progress_line_open_) std::fputc('\n', o_.progress);
    progress_line_open_ = false;
  }

  void PrintSkips() const {
    if (o_.progress == nullptr) return;
    for (const auto& [reason, count] : report_.skipped) {
      std::fprintf(o_.progress, "fusion-import: rosbag2: %llu clouds skipped: %s (first: %s)\n",
                   static_cast<unsigned long long>(count), reason.c_str(),
                   report_.first_skip.at(reason).c_str());
    }
  }

  // After a clean read: messages that did not decode and clouds none of which had a pose fail.
  Status Verdict() const {
    if (undecodable_ > 0) {
      return Status::Error(std::to_string(undecodable_) +
                           " messages do not decode (corrupt bag?); first: " + first_undecodable_);
    }
    if (report_.cloud_messages == 0)
      return Status::Error("topic " + CloudTopic() + " has no messages");
    if (report_.clouds_imported == 0) {
      std::string why;
      for (const auto& [reason, count] : report_.skipped) {
        why += (why.empty() ? "" : "; ") + std::to_string(count) + " " + reason +
               " (first: " + report_.first_skip.at(reason) + ")";
      }
      return Status::Error("none of the " + std::to_string(report_.cloud_messages) + " clouds on " +
                           CloudTopic() + " was imported: " + why);
    }
    return Status::Ok();
  }

  const Rosbag2Options& o_;
  const CloudSink& sink_;
  Rosbag2Report& report_;
  std::vector<std::string> files_;
  std::vector<BagTopic> topics_;
  std::map<std::string, std::uint64_t> counts_;  // messages by topic (first pass)
  std::vector<TfSample> tf_;
  std::vector<std::pair<double, ros2::CameraInfo>> camera_infos_;  // by stamp
  std::unique_ptr<TransformBuffer> buffer_;
  std::uint64_t undecodable_ = 0, invalid_transforms_ = 0;
  std::string first_undecodable_;
  std::vector<float> xyz_;           // reused between clouds
  bool progress_line_open_ = false;  // the running count ends the last line on progress
  // The first count after 2 s: short bags print none.
  std::chrono::steady_clock::time_point next_progress_ =
      std::chrono::steady_clock::now() + std::chrono::seconds(2);
};

}  // namespace

Status ImportRosbag2(const Rosbag2Options& options, const CloudSink& sink, Rosbag2Report* report) {
  Rosbag2Report local;
  Importer importer(options, sink, report != nullptr ? report : &local);
  return importer.Run();
}

}  // namespace fusion::clients
