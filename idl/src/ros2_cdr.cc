// XCDR1 decoding and encoding of the ROS 2 messages (fusion/ros2/cdr.h).
#include <cstring>
#include <limits>
#include <type_traits>

#include "fusion/ros2/cdr.h"

namespace fusion::ros2 {
namespace {

constexpr std::size_t kEncapsulationBytes = 4;
constexpr bool kHostBigEndian = __BYTE_ORDER__ == __ORDER_BIG_ENDIAN__;

template <class T>
T ByteSwapped(T value) {
  std::uint8_t bytes[sizeof(T)];
  std::memcpy(bytes, &value, sizeof(T));
  for (std::size_t i = 0; i < sizeof(T) / 2; ++i) std::swap(bytes[i], bytes[sizeof(T) - 1 - i]);
  std::memcpy(&value, bytes, sizeof(T));
  return value;
}

// Reads one message; the first failure is kept (with its field path) and every later read fails.
class Reader {
 public:
  Reader(ByteView buffer, const char* root) : buffer_(buffer), path_(root) {}

  // The encapsulation header; the body starts after it.
  bool Begin() {
    if (buffer_.size < kEncapsulationBytes) {
      return Fail(
          "", "encapsulation header needs 4 bytes, the buffer has " + std::to_string(buffer_.size),
          0);
    }
    if (buffer_[0] != 0 || buffer_[1] > 1) {
      static const char kHex[] = "0123456789abcdef";
      std::string id = "0x";
      for (int i = 0; i < 2; ++i) id += {kHex[buffer_[i] >> 4], kHex[buffer_[i] & 15]};
      return Fail("", "encapsulation " + id + " is not XCDR1 (CDR_BE 0x0000, CDR_LE 0x0001)", 0);
    }
    swap_ = (buffer_[1] == 0) != kHostBigEndian;
    body_ = buffer_.data + kEncapsulationBytes;
    size_ = buffer_.size - kEncapsulationBytes;
    return true;
  }

  template <class T>
  bool Prim(const char* field, T* value) {
    static_assert(std::is_arithmetic_v<T>);
    if (!Reserve(field, sizeof(T), sizeof(T), 1, "value")) return false;
    std::memcpy(value, body_ + pos_, sizeof(T));
    if (swap_ && sizeof(T) > 1) *value = ByteSwapped(*value);
    pos_ += sizeof(T);
    return true;
  }

  bool Bool(const char* field, bool* value) {
    std::uint8_t byte = 0;
    if (!Prim(field, &byte)) return false;
    if (byte > 1) return Fail(field, "boolean is " + std::to_string(byte), pos_ - 1);
    *value = byte == 1;
    return true;
  }

  bool String(const char* field, std::string* text) {
    std::uint32_t length = 0;
    if (!Prim(field, &length)) return false;
    if (length == 0) {  // some writers send "" as length 0, without the NUL
      text->clear();
      return true;
    }
    if (length > size_ - pos_) return Fail(field, "string runs past the end", pos_ - 4);
    if (body_[pos_ + length - 1] != 0) return Fail(field, "string lacks its NUL", pos_ - 4);
    text->assign(reinterpret_cast<const char*>(body_ + pos_), length - 1);
    pos_ += length;
    return true;
  }

  // A sequence's element count, checked against the bytes left (each element needs at least
  // `min_element_bytes`).
  bool Count(const char* field, std::size_t min_element_bytes, std::uint32_t* count) {
    if (!Prim(field, count)) return false;
    if (*count > (size_ - pos_) / min_element_bytes) {
      return Fail(field, "sequence of " + std::to_string(*count) + " runs past the end", pos_ - 4);
    }
    return true;
  }

  // sequence<uint8>: a view into the buffer.
  bool Bytes(const char* field, ByteView* bytes) {
    std::uint32_t count = 0;
    if (!Count(field, 1, &count)) return false;
    *bytes = ByteView(body_ + pos_, count);
    pos_ += count;
    return true;
  }

  template <class T, std::size_t N>
  bool Array(const char* field, std::array<T, N>* values) {
    if (!Reserve(field, sizeof(T), sizeof(T), N, "array")) return false;
    for (auto& v : *values) (void)Prim(field, &v);
    return true;
  }

  // Appends ".part" to the field path while in scope.
  class Scope {
   public:
    Scope(Reader* reader, const std::string& part)
        : reader_(reader), length_(reader->path_.size()) {
      reader_->path_ += "." + part;
    }
    ~Scope() { reader_->path_.resize(length_); }
    Scope(const Scope&) = delete;
    Scope& operator=(const Scope&) = delete;

   private:
    Reader* reader_;
    std::size_t length_;
  };

  [[nodiscard]] bool failed() const { return !error_.empty(); }
  [[nodiscard]] const std::string& error() const { return error_; }

 private:
  // Aligns to `alignment` and checks that `count` elements of `element_bytes` fit.
  bool Reserve(const char* field, std::size_t alignment, std::size_t element_bytes,
               std::size_t count, const char* what) {
    if (failed()) return false;
    const std::size_t aligned = (pos_ + alignment - 1) / alignment * alignment;
    if (aligned > size_ || count > (size_ - aligned) / element_bytes) {
      return Fail(field, std::string(what) + " runs past the end", pos_);
    }
    pos_ = aligned;
    return true;
  }

  bool Fail(const char* field, const std::string& what, std::size_t body_offset) {
    if (failed()) return false;
    error_ = path_ + (*field != 0 ? std::string(".") + field : std::string()) + ": " + what +
             " at byte " + std::to_string(body_offset + (body_ ? kEncapsulationBytes : 0));
    return false;
  }

  ByteView buffer_;
  const std::uint8_t* body_ = nullptr;
  std::size_t size_ = 0, pos_ = 0;
  bool swap_ = false;
  std::string path_, error_;
};

class Writer {
 public:
  explicit Writer(CdrEndian endian) : swap_((endian == CdrEndian::kBig) != kHostBigEndian) {
    bytes_ = {0, static_cast<std::uint8_t>(endian == CdrEndian::kBig ? 0 : 1), 0, 0};
  }
  template <class T>
  void Prim(T value) {
    static_assert(std::is_arithmetic_v<T>);
    while ((bytes_.size() - kEncapsulationBytes) % sizeof(T) != 0) bytes_.push_back(0);
    if (swap_ && sizeof(T) > 1) value = ByteSwapped(value);
    const auto* p = reinterpret_cast<const std::uint8_t*>(&value);
    bytes_.insert(bytes_.end(), p, p + sizeof(T));
  }
  void Bool(bool value) { Prim<std::uint8_t>(value ? 1 : 0); }
  void String(const std::string& text) {
    Prim(static_cast<std::uint32_t>(text.size() + 1));
    bytes_.insert(bytes_.end(), text.begin(), text.end());
    bytes_.push_back(0);
  }
  void Count(std::size_t count) { Prim(static_cast<std::uint32_t>(count)); }
  void Bytes(ByteView data) {
    Count(data.size);
    bytes_.insert(bytes_.end(), data.begin(), data.end());
  }
  template <class T, std::size_t N>
  void Array(const std::array<T, N>& values) {
    for (const T v : values) Prim(v);
  }
  std::vector<std::uint8_t> Take() { return std::move(bytes_); }

 private:
  bool swap_;
  std::vector<std::uint8_t> bytes_;
};

// ---- one Read and one Write per message, field for field in the published order ----

void Read(Reader& r, Time* t) {
  Reader::Scope scope(&r, "stamp");
  r.Prim("sec", &t->sec) && r.Prim("nanosec", &t->nanosec);
}
void Write(Writer& w, const Time& t) {
  w.Prim(t.sec);
  w.Prim(t.nanosec);
}

void Read(Reader& r, Header* h) {
  Reader::Scope scope(&r, "header");
  Read(r, &h->stamp);
  r.String("frame_id", &h->frame_id);
}
void Write(Writer& w, const Header& h) {
  Write(w, h.stamp);
  w.String(h.frame_id);
}

// The smallest PointField on the wire: name (length 0), offset, datatype, count.
constexpr std::size_t kMinPointFieldBytes = 13;

void Read(Reader& r, PointCloud2* m) {
  Read(r, &m->header);
  std::uint32_t fields = 0;
  if (!(r.Prim("height", &m->height) && r.Prim("width", &m->width) &&
        r.Count("fields", kMinPointFieldBytes, &fields))) {
    return;
  }
  m->fields.assign(fields, PointField{});
  for (std::uint32_t i = 0; i < fields && !r.failed(); ++i) {
    Reader::Scope scope(&r, "fields[" + std::to_string(i) + "]");
    PointField& f = m->fields[i];
    r.String("name", &f.name) && r.Prim("offset", &f.offset) && r.Prim("datatype", &f.datatype) &&
        r.Prim("count", &f.count);
  }
  r.Bool("is_bigendian", &m->is_bigendian) && r.Prim("point_step", &m->point_step) &&
      r.Prim("row_step", &m->row_step) && r.Bytes("data", &m->data) &&
      r.Bool("is_dense", &m->is_dense);
}
void Write(Writer& w, const PointCloud2& m) {
  Write(w, m.header);
  w.Prim(m.height);
  w.Prim(m.width);
  w.Count(m.fields.size());
  for (const PointField& f : m.fields) {
    w.String(f.name);
    w.Prim(f.offset);
    w.Prim(f.datatype);
    w.Prim(f.count);
  }
  w.Bool(m.is_bigendian);
  w.Prim(m.point_step);
  w.Prim(m.row_step);
  w.Bytes(m.data);
  w.Bool(m.is_dense);
}

void Read(Reader& r, Image* m) {
  Read(r, &m->header);
  r.Prim("height", &m->height) && r.Prim("width", &m->width) &&
      r.String("encoding", &m->encoding) && r.Prim("is_bigendian", &m->is_bigendian) &&
      r.Prim("step", &m->step) && r.Bytes("data", &m->data);
}
void Write(Writer& w, const Image& m) {
  Write(w, m.header);
  w.Prim(m.height);
  w.Prim(m.width);
  w.String(m.encoding);
  w.Prim(m.is_bigendian);
  w.Prim(m.step);
  w.Bytes(m.data);
}

void Read(Reader& r, CameraInfo* m) {
  Read(r, &m->header);
  std::uint32_t d = 0;
  if (!(r.Prim("height", &m->height) && r.Prim("width", &m->width) &&
        r.String("distortion_model", &m->distortion_model) && r.Count("d", 8, &d))) {
    return;
  }
  m->d.assign(d, 0.0);
  for (double& v : m->d) (void)r.Prim("d", &v);
  r.Array("k", &m->k) && r.Array("r", &m->r) && r.Array("p", &m->p) &&
      r.Prim("binning_x", &m->binning_x) && r.Prim("binning_y", &m->binning_y);
  Reader::Scope scope(&r, "roi");
  RegionOfInterest& roi = m->roi;
  r.Prim("x_offset", &roi.x_offset) && r.Prim("y_offset", &roi.y_offset) &&
      r.Prim("height", &roi.height) && r.Prim("width", &roi.width) &&
      r.Bool("do_rectify", &roi.do_rectify);
}
void Write(Writer& w, const CameraInfo& m) {
  Write(w, m.header);
  w.Prim(m.height);
  w.Prim(m.width);
  w.String(m.distortion_model);
  w.Count(m.d.size());
  for (const double v : m.d) w.Prim(v);
  w.Array(m.k);
  w.Array(m.r);
  w.Array(m.p);
  w.Prim(m.binning_x);
  w.Prim(m.binning_y);
  w.Prim(m.roi.x_offset);
  w.Prim(m.roi.y_offset);
  w.Prim(m.roi.height);
  w.Prim(m.roi.width);
  w.Bool(m.roi.do_rectify);
}

void Read(Reader& r, TransformStamped* m) {
  Read(r, &m->header);
  r.String("child_frame_id", &m->child_frame_id);
  Reader::Scope scope(&r, "transform");
  Vector3& t = m->transform.translation;
  Quaternion& q = m->transform.rotation;
  {
    Reader::Scope translation(&r, "translation");
    r.Prim("x", &t.x) && r.Prim("y", &t.y) && r.Prim("z", &t.z);
  }
  Reader::Scope rotation(&r, "rotation");
  r.Prim("x", &q.x) && r.Prim("y", &q.y) && r.Prim("z", &q.z) && r.Prim("w", &q.w);
}
void Write(Writer& w, const TransformStamped& m) {
  Write(w, m.header);
  w.String(m.child_frame_id);
  const Vector3& t = m.transform.translation;
  const Quaternion& q = m.transform.rotation;
  for (const double v : {t.x, t.y, t.z, q.x, q.y, q.z, q.w}) w.Prim(v);
}

// The smallest TransformStamped: stamp, two empty strings, seven doubles.
constexpr std::size_t kMinTransformStampedBytes = 4 + 4 + 4 + 4 + 7 * 8;

void Read(Reader& r, TFMessage* m) {
  std::uint32_t count = 0;
  if (!r.Count("transforms", kMinTransformStampedBytes, &count)) return;
  m->transforms.assign(count, TransformStamped{});
  for (std::uint32_t i = 0; i < count && !r.failed(); ++i) {
    Reader::Scope scope(&r, "transforms[" + std::to_string(i) + "]");
    Read(r, &m->transforms[i]);
  }
}
void Write(Writer& w, const TFMessage& m) {
  w.Count(m.transforms.size());
  for (const TransformStamped& t : m.transforms) Write(w, t);
}

template <class Message>
CdrResult Decode(ByteView serialized, const char* name, Message* message) {
  Reader reader(serialized, name);
  *message = Message{};
  if (reader.Begin()) Read(reader, message);
  return {reader.error()};
}

template <class Message>
std::vector<std::uint8_t> Encode(const Message& message, CdrEndian endian) {
  Writer writer(endian);
  Write(writer, message);
  return writer.Take();
}

}  // namespace

CdrResult DecodeCdr(ByteView serialized, PointCloud2* message) {
  return Decode(serialized, "PointCloud2", message);
}
CdrResult DecodeCdr(ByteView serialized, Image* message) {
  return Decode(serialized, "Image", message);
}
CdrResult DecodeCdr(ByteView serialized, CameraInfo* message) {
  return Decode(serialized, "CameraInfo", message);
}
CdrResult DecodeCdr(ByteView serialized, TFMessage* message) {
  return Decode(serialized, "TFMessage", message);
}
CdrResult DecodeCdr(ByteView serialized, TransformStamped* message) {
  return Decode(serialized, "TransformStamped", message);
}
CdrResult DecodeCdr(ByteView serialized, Header* message) {
  Reader reader(serialized, "Header");
  *message = Header{};
  if (reader.Begin()) {
    Read(reader, &message->stamp);
    reader.String("frame_id", &message->frame_id);
  }
  return {reader.error()};
}

std::vector<std::uint8_t> EncodeCdr(const PointCloud2& message, CdrEndian endian) {
  return Encode(message, endian);
}
std::vector<std::uint8_t> EncodeCdr(const Image& message, CdrEndian endian) {
  return Encode(message, endian);
}
std::vector<std::uint8_t> EncodeCdr(const CameraInfo& message, CdrEndian endian) {
  return Encode(message, endian);
}
std::vector<std::uint8_t> EncodeCdr(const TFMessage& message, CdrEndian endian) {
  return Encode(message, endian);
}
std::vector<std::uint8_t> EncodeCdr(const TransformStamped& message, CdrEndian endian) {
  return Encode(message, endian);
}
std::vector<std::uint8_t> EncodeCdr(const Header& message, CdrEndian endian) {
  return Encode(message, endian);
}

}  // namespace fusion::ros2
