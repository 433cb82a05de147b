// Plain C++ mirrors of the ROS 2 messages fusiond and fusion-import read (sensor_msgs,
// std_msgs, builtin_interfaces, geometry_msgs, tf2_msgs), field for field in the order and with
// the types of their published definitions, so that XCDR1 (ros2/cdr.h) maps one to the other.
// No ROS 2 and no DDS types here: the service decodes its DDS samples into these, and the bag
// importer decodes the bags' serialized messages into them.
//
// The large byte arrays (`data`) are borrowed views: a decoded message points into the buffer it
// was decoded from (a DDS sample, a bag's chunk), so nothing is copied; the buffer must outlive
// the message. Owned<M> keeps a message and its bytes together where it must outlive them.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace fusion::ros2 {

// Bytes owned elsewhere (a DDS sample, a serialized message, a vector).
struct ByteView {
  const std::uint8_t* data = nullptr;
  std::size_t size = 0;

  ByteView() = default;
  ByteView(const std::uint8_t* d, std::size_t n) : data(d), size(n) {}
  explicit ByteView(const std::vector<std::uint8_t>& bytes)
      : data(bytes.data()), size(bytes.size()) {}
  [[nodiscard]] bool empty() const { return size == 0; }
  [[nodiscard]] const std::uint8_t* begin() const { return data; }
  [[nodiscard]] const std::uint8_t* end() const { return data + size; }
  std::uint8_t operator[](std::size_t i) const { return data[i]; }
};

// builtin_interfaces/Time.
struct Time {
  std::int32_t sec = 0;
  std::uint32_t nanosec = 0;
  // Seconds since the epoch (double: ~0.2 us resolution today).
  [[nodiscard]] double seconds() const { return sec + 1e-9 * nanosec; }
};

// std_msgs/Header.
struct Header {
  Time stamp;
  std::string frame_id;
};

// sensor_msgs/PointField.
struct PointField {
  static constexpr std::uint8_t INT8 = 1;
  static constexpr std::uint8_t UINT8 = 2;
  static constexpr std::uint8_t INT16 = 3;
  static constexpr std::uint8_t UINT16 = 4;
  static constexpr std::uint8_t INT32 = 5;
  static constexpr std::uint8_t UINT32 = 6;
  static constexpr std::uint8_t FLOAT32 = 7;
  static constexpr std::uint8_t FLOAT64 = 8;

  std::string name;
  std::uint32_t offset = 0;  // bytes from the start of the point
  std::uint8_t datatype = 0;
  std::uint32_t count = 0;  // elements in the field
};

// sensor_msgs/PointCloud2.
struct PointCloud2 {
  Header header;
  std::uint32_t height = 0;  // 1 = unorganized
  std::uint32_t width = 0;
  std::vector<PointField> fields;
  bool is_bigendian = false;
  std::uint32_t point_step = 0;  // bytes a point
  std::uint32_t row_step = 0;    // bytes a row
  ByteView data;                 // row_step * height bytes
  bool is_dense = false;
};

// sensor_msgs/Image.
struct Image {
  Header header;
  std::uint32_t height = 0;
  std::uint32_t width = 0;
  std::string encoding;  // e.g. "16UC1" (depth in mm), "32FC1" (depth in m)
  std::uint8_t is_bigendian = 0;
  std::uint32_t step = 0;  // bytes a row
  ByteView data;           // step * height bytes
};

// sensor_msgs/RegionOfInterest.
struct RegionOfInterest {
  std::uint32_t x_offset = 0;
  std::uint32_t y_offset = 0;
  std::uint32_t height = 0;
  std::uint32_t width = 0;
  bool do_rectify = false;
};

// sensor_msgs/CameraInfo. k = [fx 0 cx; 0 fy cy; 0 0 1] row-major (pixels).
struct CameraInfo {
  Header header;
  std::uint32_t height = 0;
  std::uint32_t width = 0;
  std::string distortion_model;
  std::vector<double> d;
  std::array<double, 9> k{};
  std::array<double, 9> r{};
  std::array<double, 12> p{};
  std::uint32_t binning_x = 0;
  std::uint32_t binning_y = 0;
  RegionOfInterest roi;
};

// geometry_msgs/Vector3, Quaternion (Hamilton, x y z w), Transform.
struct Vector3 {
  double x = 0, y = 0, z = 0;
};
struct Quaternion {
  double x = 0, y = 0, z = 0, w = 1;
};
struct Transform {
  Vector3 translation;  // metres
  Quaternion rotation;
};

// geometry_msgs/TransformStamped: the pose of child_frame_id in header.frame_id,
// T_parent_child.
struct TransformStamped {
  Header header;
  std::string child_frame_id;
  Transform transform;
};

// tf2_msgs/TFMessage (/tf, /tf_static).
struct TFMessage {
  std::vector<TransformStamped> transforms;
};

// A message together with the bytes its views point into; copies share the bytes.
template <class Message>
struct Owned {
  Message message;
  std::shared_ptr<const std::vector<std::uint8_t>> bytes;
};

// Copies the bytes `message.data` points to and re-points the copy's view at them.
template <class Message>
Owned<Message> MakeOwned(const Message& message) {
  auto bytes =
      std::make_shared<const std::vector<std::uint8_t>>(message.data.begin(), message.data.end());
  Owned<Message> owned{message, bytes};
  owned.message.data = ByteView(*bytes);
  return owned;
}

}  // namespace fusion::ros2
