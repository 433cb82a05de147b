// fusion_fuzz_seeds OUT_DIR ROOT [SHARED_DATA_DIR]: writes small seed inputs for every fuzz
// target into OUT_DIR/<target>/ and says which of them the parsers refuse. Real samples
// (../shared/data) are cut small: a few dozen scan points, a 32 x 24 crop of a TUM depth frame,
// 8 points of the PCL stereo frame. Without SHARED_DATA_DIR the seeds are synthetic.
// Configuration seeds come from ROOT's example files.
// fusion_fuzz_seeds --replay TARGET FILE: one input's verdict (e.g. a crash artifact).
#include <google/protobuf/text_format.h>
#include <google/protobuf/util/json_util.h>
#include <octomap/ScanGraph.h>
#include <png.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "fusion/clients/importers.h"
#include "fusion/clients/recording.h"
#include "fusion/ros2/cdr.h"
#include "fusion/service/config.h"
#include "fusion/service/persistence.h"
#include "fuzz_entries.h"

namespace {

namespace fs = std::filesystem;
using fusion::v1::RecordedCloud;
using Points = std::vector<std::array<float, 3>>;

std::string g_out;     // OUT_DIR
std::string g_shared;  // "" without real data

std::vector<std::pair<std::string, std::string>> g_written;  // target, file name

void Put(const std::string& target, const std::string& name, const std::string& bytes) {
  fs::create_directories(g_out + "/" + target);
  std::ofstream(g_out + "/" + target + "/" + name, std::ios::binary) << bytes;
  g_written.emplace_back(target, name);
}

std::string Slurp(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

bool Have(const std::string& relative) {
  return !g_shared.empty() && fs::exists(g_shared + "/" + relative);
}

// The real laser scan (read once), or no clouds.
const std::vector<RecordedCloud>& RealScan() {
  static const std::vector<RecordedCloud> clouds = [] {
    std::vector<RecordedCloud> read;
    fusion::v1::RecordedPose identity;
    identity.set_qw(1);
    if (!Have("octomap_laser_scan/scan.dat.bz2") ||
        !fusion::clients::ReadXyzScan(g_shared + "/octomap_laser_scan/scan.dat.bz2", identity,
                                      &read)
             .ok()) {
      read.clear();
    }
    return read;
  }();
  return clouds;
}

// The first `n` points of the real laser scan, or a synthetic arc.
Points ScanPoints(std::size_t n) {
  Points points;
  if (!RealScan().empty() && RealScan()[0].width() >= n) {
    for (std::size_t i = 0; i < n; ++i) {
      std::array<float, 3> p;
      fusion::clients::GetPoint(RealScan()[0], i, p.data());
      points.push_back(p);
    }
    return points;
  }
  for (std::size_t i = 0; i < n; ++i) {
    const float a = 0.05f * static_cast<float>(i);
    points.push_back({2.0f * std::cos(a), 2.0f * std::sin(a), 0.1f * static_cast<float>(i % 5)});
  }
  return points;
}

RecordedCloud CloudOf(const Points& points, const std::string& id, std::uint64_t sequence) {
  RecordedCloud cloud;
  for (const auto& p : points) fusion::clients::AppendPoint(p[0], p[1], p[2], &cloud);
  cloud.set_width(static_cast<std::uint32_t>(points.size()));
  cloud.set_height(1);
  cloud.mutable_t_world_sensor()->set_qw(1);
  fusion::clients::SetIdentity(id, sequence, 1.7e9 + static_cast<double>(sequence), "seed", &cloud);
  return cloud;
}

// ---------------------------------------------------------------------------------------------

void DdsSeeds() {
  fusion::fuzz::DdsSampleSeed seed;
  Put("dds_sample", "valid_2x1", fusion::fuzz::EncodeDdsSample(seed));
  seed.beyond_range = {0, 1};
  seed.pose[0] = 2.0;
  Put("dds_sample", "beyond_range", fusion::fuzz::EncodeDdsSample(seed));
  const Points scan = ScanPoints(24);
  seed = {};
  seed.sensor_id = "stoc";
  seed.width = 6, seed.height = 4, seed.xyz.clear();
  for (const auto& p : scan) seed.xyz.insert(seed.xyz.end(), p.begin(), p.end());
  seed.xyz[3] = seed.xyz[4] = seed.xyz[5] = NAN;
  const double h = std::sqrt(0.5);
  seed.pose[3] = h, seed.pose[6] = h;  // 90 degrees about x
  Put("dds_sample", "scan_6x4", fusion::fuzz::EncodeDdsSample(seed));
  seed.sensor_id = "elsewhere";
  Put("dds_sample", "unknown_sensor", fusion::fuzz::EncodeDdsSample(seed));
}

void ConfigSeeds(const std::string& root) {
  std::vector<std::pair<std::string, std::string>> texts = {
      {"minimal", "dds_domain: 42\nlog_level: \"debug\"\n"},
      {"custom_sensor",
       "sensors { id: \"tof\" model: \"classic_beam\" r_min_m: 0.3 r_max_m: 7.5 fov_h_deg: 47.5\n"
       "  fov_v_deg: 39.6 cols: 176 rows: 144 q_mu { a2: 0.001 a1: 0.01 a0: 0 }\n"
       "  q_sigma { a0: 0.01 } epsilon: 0.02 queue_depth: 8\n"
       "  mount { tx: 0.025 ty: 0 tz: -0.08 qx: 0 qy: 0 qz: 0 qw: 1 } }\n"
       "map { resolution_m: 0.02 fusion_rule: \"max\" max_range_m: 4 render_threads: 1 }\n"
       "ingest { reliability: \"reliable\" max_points: 1000 }\n"},
  };
  std::string defaults;
  google::protobuf::TextFormat::PrintToString(fusion::service::DefaultConfig(), &defaults);
  texts.emplace_back("defaults", defaults);
  for (const char* file : {"docs/fusiond.example.pbtxt", "docker/fusiond.pbtxt"}) {
    texts.emplace_back(fs::path(file).stem().string(), Slurp(root + "/" + file));
  }
  for (const auto& [name, text] : texts) {
    Put("config_text", name + ".pbtxt", text);
    fusion::v1::ServiceConfig config;
    std::string json;
    if (google::protobuf::TextFormat::ParseFromString(text, &config) &&
        google::protobuf::util::MessageToJsonString(config, &json).ok()) {
      Put("config_json", name + ".json", json);
    }
  }
}

void RecordingSeeds() {
  const std::string path = g_out + "/recording.tmp";
  std::unique_ptr<fusion::clients::RecordingWriter> writer;
  if (!fusion::clients::RecordingWriter::Create(path, "seeds", "fuzz", &writer).ok()) return;
  Put("recording", "header_only_unclosed", Slurp(path));
  const Points scan = ScanPoints(16);
  (void)writer->Append(CloudOf(Points(scan.begin(), scan.begin() + 8), "sr", 1));
  (void)writer->Append(CloudOf(Points(scan.begin() + 8, scan.end()), "stoc", 1));
  Put("recording", "two_records_unclosed", Slurp(path));
  (void)writer->Close();
  Put("recording", "two_records_indexed", Slurp(path));
  fs::remove(path);
}

// ---------------------------------------------------------------------------------------------
// Importers

// LZF with literal runs only: valid for any decompressor.
std::string LzfLiterals(const std::string& raw) {
  std::string out;
  for (std::size_t i = 0; i < raw.size(); i += 32) {
    const std::size_t n = std::min<std::size_t>(32, raw.size() - i);
    out.push_back(static_cast<char>(n - 1));
    out.append(raw, i, n);
  }
  return out;
}

// 8 finite points of the PCL stereo frame (x y z rgb), or synthetic ones.
Points StereoPoints() {
  Points points;
  RecordedCloud cloud;
  const std::string path = g_shared + "/pcl_stereo/table_scene_mug_stereo_textured.pcd";
  if (Have("pcl_stereo/table_scene_mug_stereo_textured.pcd") &&
      fusion::clients::ReadPcd(path, &cloud, false).ok()) {
    for (std::size_t i = 0; i < cloud.width() * cloud.height() && points.size() < 8; i += 997) {
      std::array<float, 3> p;
      fusion::clients::GetPoint(cloud, i, p.data());
      if (std::isfinite(p[0]) && std::isfinite(p[1]) && std::isfinite(p[2])) points.push_back(p);
    }
  }
  for (float i = 0; points.size() < 8; ++i) points.push_back({0.1f * i, -0.2f, 0.7f + 0.05f * i});
  return points;
}

std::string PcdHeader(const std::string& data, const std::string& viewpoint) {
  return "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS x y z rgb\n"
         "SIZE 4 4 4 4\nTYPE F F F U\nCOUNT 1 1 1 1\nWIDTH 4\nHEIGHT 2\nVIEWPOINT " +
         viewpoint + "\nPOINTS 8\nDATA " + data + "\n";
}

void PcdSeeds() {
  const Points points = StereoPoints();
  std::ostringstream ascii;
  std::string binary, columns[4];
  for (const auto& p : points) {
    const std::uint32_t rgb = 0x00a0b0c0;
    char line[96];
    std::snprintf(line, sizeof line, "%.9g %.9g %.9g %u\n", p[0], p[1], p[2], rgb);
    ascii << line;
    binary.append(reinterpret_cast<const char*>(p.data()), 12);
    binary.append(reinterpret_cast<const char*>(&rgb), 4);
    for (int f = 0; f < 3; ++f) columns[f].append(reinterpret_cast<const char*>(&p[f]), 4);
    columns[3].append(reinterpret_cast<const char*>(&rgb), 4);
  }
  const std::string raw = columns[0] + columns[1] + columns[2] + columns[3];
  const std::string lzf = LzfLiterals(raw);
  const std::uint32_t sizes[2] = {static_cast<std::uint32_t>(lzf.size()),
                                  static_cast<std::uint32_t>(raw.size())};
  const std::string real_viewpoint = "0 0 0 0 1 0 0";
  Put("pcd", "ascii.pcd", PcdHeader("ascii", "0 0 0 1 0 0 0") + ascii.str());
  Put("pcd", "binary.pcd", PcdHeader("binary", real_viewpoint) + binary);
  Put("pcd", "binary_compressed.pcd",
      PcdHeader("binary_compressed", "1 0 0 0.7071068 0 0 0.7071068") +
          std::string(reinterpret_cast<const char*>(sizes), 8) + lzf);
  Put("pcd", "doubles_unorganized.pcd",
      "VERSION .7\nFIELDS x y z\nSIZE 8 8 8\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 2\nHEIGHT 1\n"
      "DATA ascii\n1.5 nan 2\n0 0 1e-3\n");
  if (Have("pcl_stereo/table_scene_mug_stereo_textured.pcd")) {  // the real header, cut short
    Put("pcd", "real_cut_2k.pcd",
        Slurp(g_shared + "/pcl_stereo/table_scene_mug_stereo_textured.pcd").substr(0, 2048));
  }
}

// A 16-bit grayscale PNG.
std::string Png16(std::uint32_t width, std::uint32_t height, const std::vector<std::uint16_t>& v) {
  const std::string path = g_out + "/png.tmp";
  std::FILE* file = std::fopen(path.c_str(), "wb");
  png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, nullptr, nullptr, nullptr);
  png_infop info = png_create_info_struct(png);
  png_init_io(png, file);
  png_set_IHDR(png, info, width, height, 16, PNG_COLOR_TYPE_GRAY, PNG_INTERLACE_NONE,
               PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
  png_write_info(png, info);
  png_set_swap(png);  // host little-endian -> PNG big-endian
  for (std::uint32_t y = 0; y < height; ++y) {
    png_write_row(png, reinterpret_cast<png_const_bytep>(v.data() + std::size_t{y} * width));
  }
  png_write_end(png, nullptr);
  png_destroy_write_struct(&png, &info);
  std::fclose(file);
  const std::string bytes = Slurp(path);
  fs::remove(path);
  return bytes;
}

// A 32 x 24 crop around the centre of the first real depth frame, or a synthetic ramp.
std::vector<std::uint16_t> DepthCrop(const std::string& png_path) {
  std::uint32_t w = 0, h = 0;
  std::vector<std::uint16_t> full, crop;
  if (!png_path.empty() && fusion::clients::ReadPng16(png_path, &w, &h, &full).ok() && w >= 32 &&
      h >= 24) {
    for (std::uint32_t y = h / 2 - 12; y < h / 2 + 12; ++y) {
      for (std::uint32_t x = w / 2 - 16; x < w / 2 + 16; ++x) crop.push_back(full[y * w + x]);
    }
    return crop;
  }
  for (std::uint32_t i = 0; i < 32 * 24; ++i) crop.push_back(i % 7 == 0 ? 0 : 5000 + 3 * i);
  return crop;
}

void TumSeeds() {
  std::string lines =
      "# depth_file tx ty tz qx qy qz qw\n"
      "depth/1311877813.991479.png -2.2591 -2.38 0.5901 0.1909 0.7167 -0.6507 -0.1627\n";
  std::string first_png;
  if (Have("tum_fr2_pioneer_slam2/groundtruth.txt")) {
    std::istringstream real(Slurp(g_shared + "/tum_fr2_pioneer_slam2/groundtruth.txt"));
    lines.clear();
    // The comment, the first frame, and the second frame's pose on the first frame's PNG.
    std::string line;
    while (std::getline(real, line) && (line.empty() || line[0] == '#')) lines += line + "\n";
    first_png = line.substr(0, line.find(' '));
    lines += line + "\n";
    if (std::getline(real, line)) lines += first_png + line.substr(line.find(' ')) + "\n";
    first_png = g_shared + "/tum_fr2_pioneer_slam2/" + first_png;
  }
  const std::string crop = Png16(32, 24, DepthCrop(first_png));
  Put("tum", "frame_32x24", lines + std::string(1, '\0') + crop);
  Put("tum", "tiny_2x2",
      "depth/1.5.png 0 0 0 0 0 0 1\n" + std::string(1, '\0') + Png16(2, 2, {0, 1000, 65535, 5000}));
}

void XyzSeeds() {
  const Points scan = ScanPoints(40);
  std::ostringstream plain, nodes;
  nodes << "# two nodes, OctoMap log format\nNODE 0 0 0 0 0 0\n";
  for (std::size_t i = 0; i < scan.size(); ++i) {
    char line[80];
    std::snprintf(line, sizeof line, "%.6g %.6g %.6g\n", scan[i][0], scan[i][1], scan[i][2]);
    plain << line;
    if (i == scan.size() / 2) nodes << "NODE 1.5 -0.5 0.2 0 0 1.5708\n";
    nodes << line;
  }
  Put("xyz_scan", "scan_40_points.txt", plain.str());
  Put("xyz_scan", "two_nodes.txt", nodes.str());
}

void ScanGraphSeeds() {
  const Points scan = ScanPoints(20);
  octomap::ScanGraph graph;
  octomap::ScanNode* nodes[2];
  for (int n = 0; n < 2; ++n) {
    auto* cloud = new octomap::Pointcloud();
    for (int i = 0; i < 10; ++i) {
      const auto& p = scan[static_cast<std::size_t>(10 * n + i)];
      cloud->push_back(p[0], p[1], p[2]);
    }
    nodes[n] = graph.addNode(cloud, octomap::pose6d(n * 0.5, 0, 0, 0, 0, n * 0.3));
  }
  graph.addEdge(nodes[0], nodes[1], octomap::pose6d(0.5, 0, 0, 0, 0, 0.3));
  const std::string path = g_out + "/graph.tmp";
  graph.writeBinary(path);
  Put("scan_graph", "two_nodes.graph", Slurp(path));
  fs::remove(path);
}

void SnapshotSeeds() {
  octomap::OcTree tiny(0.05);
  tiny.updateNode(octomap::point3d(1.0f, 0.0f, 0.0f), true);
  tiny.updateNode(octomap::point3d(0.5f, 0.0f, 0.0f), false);
  Put("snapshot", "two_voxels.ot", fusion::service::SerializeOt(tiny));
  octomap::OcTree scan_tree(0.05);
  for (const auto& p : ScanPoints(30))
    scan_tree.updateNode(octomap::point3d(p[0], p[1], p[2]), true);
  scan_tree.updateNode(octomap::point3d(0.1f, 0.1f, 0.1f), false);
  Put("snapshot", "scan_30_points.ot", fusion::service::SerializeOt(scan_tree));
  Put("snapshot", "empty.ot", fusion::service::SerializeOt(octomap::OcTree(0.05)));
}

// Replays the seeds just written: a seed the parser refuses only exercises its error paths,
// so say which (the corpus folders also hold what the fuzzers added; those are not replayed).
int ReportVerdicts() {
  int broken = 0;
  for (const auto& [target, entry] : fusion::fuzz::AllEntries()) {
    int accepted = 0, refused = 0;
    for (const auto& [written_target, name] : g_written) {
      if (written_target != target) continue;
      const std::string bytes = Slurp(g_out + "/" + target + "/" + name);
      const auto o = entry(reinterpret_cast<const std::uint8_t*>(bytes.data()), bytes.size());
      accepted += o.verdict == fusion::fuzz::Verdict::kAccepted;
      refused += o.verdict != fusion::fuzz::Verdict::kAccepted;
      broken += o.verdict == fusion::fuzz::Verdict::kBroken;
      if (o.verdict != fusion::fuzz::Verdict::kAccepted) {
        std::printf("  %s/%s refused: %.160s\n", target, name.c_str(), o.message.c_str());
      }
    }
    std::printf("%-12s %d seeds accepted, %d refused\n", target, accepted, refused);
  }
  return broken == 0 ? 0 : 1;
}

// --replay TARGET FILE: the entry's verdict and message for one input (e.g. a crash artifact).
int Replay(const std::string& target, const std::string& path) {
  for (const auto& [name, entry] : fusion::fuzz::AllEntries()) {
    if (name != target) continue;
    const std::string bytes = Slurp(path);
    const auto o = entry(reinterpret_cast<const std::uint8_t*>(bytes.data()), bytes.size());
    static const char* const kVerdicts[] = {"accepted", "rejected", "BROKEN"};
    std::printf("%s: %s %s\n", path.c_str(), kVerdicts[static_cast<int>(o.verdict)],
                o.message.c_str());
    return o.verdict == fusion::fuzz::Verdict::kBroken ? 1 : 0;
  }
  std::fprintf(stderr, "no fuzz target '%s'\n", target.c_str());
  return 2;
}

// ---------------------------------------------------------------------------------------------
// ROS 2 messages (XCDR1): a small organized PointCloud2 in both byte orders with a padded
// layout, depth images 16UC1 / 32FC1, a CameraInfo and a TFMessage.

std::string Cdr(const std::vector<std::uint8_t>& bytes) {
  return std::string(bytes.begin(), bytes.end());
}

void Ros2Seeds() {
  const Points scan = ScanPoints(6);
  std::vector<std::uint8_t> data(6 * 16 + 2 * 4, 0);
  for (std::size_t i = 0; i < 6; ++i) {
    std::memcpy(&data[(i / 3) * 52 + (i % 3) * 16], scan[i].data(), 12);
  }
  fusion::ros2::PointCloud2 cloud;
  cloud.header = {{1700000000, 5}, "lidar"};
  cloud.height = 2, cloud.width = 3;
  cloud.fields = {{"x", 0, fusion::ros2::PointField::FLOAT32, 1},
                  {"y", 4, fusion::ros2::PointField::FLOAT32, 1},
                  {"z", 8, fusion::ros2::PointField::FLOAT32, 1},
                  {"intensity", 12, fusion::ros2::PointField::FLOAT32, 1}};
  cloud.point_step = 16, cloud.row_step = 52;
  cloud.data = fusion::ros2::ByteView(data);
  Put("ros2_cdr", "cloud_3x2_le", Cdr(fusion::ros2::EncodeCdr(cloud)));
  cloud.is_bigendian = true;  // the floats are host order: other values, same layout
  Put("ros2_cdr", "cloud_3x2_be",
      Cdr(fusion::ros2::EncodeCdr(cloud, fusion::ros2::CdrEndian::kBig)));
  fusion::ros2::Image image;
  image.header = {{1700000000, 2}, "camera_depth_optical_frame"};
  image.width = 4, image.height = 3, image.encoding = "16UC1", image.step = 8;
  std::vector<std::uint8_t> depth(24);
  for (std::size_t i = 0; i < depth.size(); i += 2) depth[i] = 0xD0, depth[i + 1] = 0x07;  // 2 m
  image.data = fusion::ros2::ByteView(depth);
  Put("ros2_cdr", "depth_16uc1", Cdr(fusion::ros2::EncodeCdr(image)));
  image.encoding = "32FC1", image.width = 2, image.step = 8;
  Put("ros2_cdr", "depth_32fc1_be",
      Cdr(fusion::ros2::EncodeCdr(image, fusion::ros2::CdrEndian::kBig)));
  fusion::ros2::CameraInfo info;
  info.header = image.header;
  info.width = 4, info.height = 3, info.distortion_model = "plumb_bob", info.d = {0, 0, 0, 0, 0};
  info.k = {520.9, 0, 325.1, 0, 521.0, 249.7, 0, 0, 1};
  Put("ros2_cdr", "camera_info", Cdr(fusion::ros2::EncodeCdr(info)));
  fusion::ros2::TFMessage tf;
  tf.transforms.resize(2);
  tf.transforms[0].header.frame_id = "map", tf.transforms[0].child_frame_id = "base_link";
  tf.transforms[1].header.frame_id = "base_link", tf.transforms[1].child_frame_id = "lidar";
  tf.transforms[1].transform.translation = {0.1, 0, 0.3};
  Put("ros2_cdr", "tf_two", Cdr(fusion::ros2::EncodeCdr(tf)));
}

}  // namespace

int main(int argc, char** argv) {
  if (argc == 4 && std::string(argv[1]) == "--replay") return Replay(argv[2], argv[3]);
  if (argc < 3 || argc > 4) {
    std::fprintf(stderr,
                 "usage: %s OUT_DIR ROOT [SHARED_DATA_DIR]\n"
                 "       %s --replay TARGET FILE\n",
                 argv[0], argv[0]);
    return 2;
  }
  g_out = argv[1];
  g_shared = argc == 4 ? argv[3] : "";
  fs::create_directories(g_out);
  DdsSeeds();
  ConfigSeeds(argv[2]);
  RecordingSeeds();
  PcdSeeds();
  TumSeeds();
  XyzSeeds();
  ScanGraphSeeds();
  SnapshotSeeds();
  Ros2Seeds();
  std::printf("seeds written to %s (%s)\n", g_out.c_str(),
              g_shared.empty() ? "synthetic only" : ("real samples from " + g_shared).c_str());
  return ReportVerdicts();
}
