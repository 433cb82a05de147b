// OctoMap binary scan graphs (.graph): validated byte by byte before OctoMap reads them.
#include <octomap/ScanGraph.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <fstream>

#include "fusion/clients/importers.h"

namespace fusion::clients {

namespace {

// octomap::ScanGraph::readBinary trusts its input (a garbage file asserts or allocates
// gigabytes), so walk the layout first. OctoMap 1.9 writes, little-endian:
//   uint32 nodes, nodes x {uint32 points, points x vec3, pose, uint32 id},
//   uint32 edges, edges x {uint32 first_id, uint32 second_id, pose, double weight}
// with vec3 = int32 3 + 3 doubles, quaternion = int32 4 + 4 doubles, pose = vec3 quaternion.
Status ValidateScanGraph(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return Status::Error("cannot open " + path + ": " + std::strerror(errno));
  const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  std::size_t pos = 0;
  const auto error = [&](const std::string& what) {
    return Status::Error(path + ": not an OctoMap binary scan graph: " + what + " at byte " +
                         std::to_string(pos));
  };
  const auto u32 = [&](std::uint32_t* v) {
    if (bytes.size() - pos < 4) return false;
    std::memcpy(v, bytes.data() + pos, 4);
    pos += 4;
    return true;
  };
  const auto vector_of = [&](std::uint32_t n) {  // marker n + n doubles
    std::uint32_t marker = 0;
    if (!u32(&marker) || marker != n || bytes.size() - pos < 8u * n) return false;
    pos += 8u * n;
    return true;
  };
  std::uint32_t nodes = 0, edges = 0;
  if (!u32(&nodes)) return error("no node count");
  if (nodes == 0 || nodes > bytes.size() / 72)
    return error("implausible node count " + std::to_string(nodes));
  std::vector<std::uint32_t> ids;
  for (std::uint32_t n = 0; n < nodes; ++n) {
    std::uint32_t points = 0, id = 0;
    if (!u32(&points)) return error("node " + std::to_string(n) + ": no point count");
    if (points > (bytes.size() - pos) / 28)
      return error("node " + std::to_string(n) + ": point count " + std::to_string(points) +
                   " exceeds the file");
    for (std::uint32_t i = 0; i < points; ++i) {
      if (!vector_of(3))
        return error("node " + std::to_string(n) + " point " + std::to_string(i) + ": bad vector");
    }
    if (!vector_of(3) || !vector_of(4)) return error("node " + std::to_string(n) + ": bad pose");
    if (!u32(&id)) return error("node " + std::to_string(n) + ": no id");
    ids.push_back(id);
  }
  if (!u32(&edges)) return error("no edge count");
  if (edges > (bytes.size() - pos) / 80)
    return error("edge count " + std::to_string(edges) + " exceeds the file");
  for (std::uint32_t e = 0; e < edges; ++e) {
    std::uint32_t first = 0, second = 0;
    if (!u32(&first) || !u32(&second)) return error("edge " + std::to_string(e) + ": no node ids");
    if (std::find(ids.begin(), ids.end(), first) == ids.end() ||
        std::find(ids.begin(), ids.end(), second) == ids.end()) {
      return error("edge " + std::to_string(e) + ": unknown node id");
    }
    if (!vector_of(3) || !vector_of(4) || bytes.size() - pos < 8)
      return error("edge " + std::to_string(e) + ": bad constraint");
    pos += 8;
  }
  if (pos != bytes.size()) return error(std::to_string(bytes.size() - pos) + " trailing bytes");
  return Status::Ok();
}

}  // namespace

Status ReadScanGraph(const std::string& path, std::vector<fusion::v1::RecordedCloud>* clouds) {
  if (Status s = ValidateScanGraph(path); !s.ok()) return s;
  octomap::ScanGraph graph;
  if (!graph.readBinary(path)) return Status::Error(path + ": not a readable OctoMap scan graph");
  if (graph.size() == 0) return Status::Error(path + ": the scan graph has no nodes");
  clouds->clear();
  for (const octomap::ScanNode* node : graph) {
    fusion::v1::RecordedCloud cloud;
    auto* pose = cloud.mutable_t_world_sensor();
    pose->set_tx(node->pose.x());
    pose->set_ty(node->pose.y());
    pose->set_tz(node->pose.z());
    pose->set_qw(node->pose.rot().u());
    pose->set_qx(node->pose.rot().x());
    pose->set_qy(node->pose.rot().y());
    pose->set_qz(node->pose.rot().z());
    const octomap::Pointcloud* scan = node->scan;
    const std::size_t n = scan != nullptr ? scan->size() : 0;
    cloud.mutable_xyz_f32le()->reserve(n * 12);
    for (std::size_t i = 0; i < n; ++i) {
      const octomap::point3d& p = (*scan)[i];
      AppendPoint(p.x(), p.y(), p.z(), &cloud);
    }
    cloud.set_width(static_cast<std::uint32_t>(n));
    cloud.set_height(1);
    clouds->push_back(std::move(cloud));
  }
  return Status::Ok();
}

}  // namespace fusion::clients
