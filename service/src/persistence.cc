#include "fusion/service/persistence.h"

#include <fcntl.h>
#include <signal.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cmath>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <vector>

namespace fusion::service {
namespace {

std::string Errno(const std::string& what) { return what + ": " + std::strerror(errno); }

bool WriteAll(int fd, const std::string& data) {
  std::size_t done = 0;
  while (done < data.size()) {
    const ssize_t n = ::write(fd, data.data() + done, data.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) return false;
    done += static_cast<std::size_t>(n);
  }
  return true;
}

std::string DirectoryOf(const std::string& path) {
  const auto slash = path.rfind('/');
  if (slash == std::string::npos) return ".";
  return slash == 0 ? "/" : path.substr(0, slash);
}

std::string UtcStamp() {
  const std::time_t now = std::time(nullptr);
  std::tm tm{};
  gmtime_r(&now, &tm);
  char buffer[32];
  std::strftime(buffer, sizeof buffer, "%Y%m%dT%H%M%SZ", &tm);
  return buffer;
}

// Parses the .ot header ("# Octomap OcTree file", "id X", "size N", "res R", "data") and
// leaves `in` at the first data byte.
bool ParseHeader(std::istream& in, std::string* id, std::uint64_t* size, double* res) {
  std::string line;
  if (!std::getline(in, line) || line.rfind("# Octomap OcTree file", 0) != 0) return false;
  bool have_id = false, have_size = false, have_res = false;
  while (std::getline(in, line)) {
    if (!line.empty() && line[0] == '#') continue;
    std::istringstream fields(line);
    std::string token;
    fields >> token;
    if (token == "id")
      have_id = static_cast<bool>(fields >> *id);
    else if (token == "size")
      have_size = static_cast<bool>(fields >> *size);
    else if (token == "res")
      have_res = static_cast<bool>(fields >> *res);
    else if (token == "data")
      return have_id && have_size && have_res;
    else
      return false;
  }
  return false;
}

}  // namespace

namespace {

// OctoMap's .ot node data, checked without building anything: every node is 4 bytes of
// log-odds and a byte of child flags, children follow their parent depth first. OctoMap's own
// reader recurses once per level and trusts the flags, so a crafted chain of 200 k nodes
// overflowed the stack. Here: an explicit stack, at most 16 levels below the root, finite
// values, and exactly `nodes` nodes in `data`. Empty if the structure holds, else the problem.
std::string CheckOtNodes(const std::string& data, std::uint64_t nodes) {
  constexpr int kMaxDepth = 16;  // octomap's tree_depth
  // An empty map (no root) is what OcTree::write gives before anything was fused.
  if (nodes == 0) return data.empty() ? std::string() : "no nodes declared, but data follows";
  std::uint64_t read = 0;
  std::size_t at = 0;
  const auto next = [&](std::uint8_t* children) -> std::string {
    if (read == nodes || at + 5 > data.size()) {
      return "its child flags ask for more than the " + std::to_string(nodes) +
             " nodes the header declares";
    }
    float log_odds = 0.0f;
    std::memcpy(&log_odds, data.data() + at, sizeof log_odds);
    *children = static_cast<std::uint8_t>(data[at + 4]);
    at += 5;
    ++read;
    if (!std::isfinite(log_odds)) return "node " + std::to_string(read) + " is not finite";
    return {};
  };
  struct Open {
    int depth;
    std::uint8_t pending;  // children not yet read
  };
  std::vector<Open> stack;
  std::uint8_t children = 0;
  if (std::string problem = next(&children); !problem.empty()) return problem;
  stack.push_back({0, children});
  while (!stack.empty()) {
    Open& top = stack.back();
    if (top.pending == 0) {
      stack.pop_back();
      continue;
    }
    top.pending &= static_cast<std::uint8_t>(top.pending - 1);  // the lowest child: read it
    const int depth = top.depth + 1;
    if (depth > kMaxDepth) return "it is deeper than OctoMap's 16 levels";
    if (std::string problem = next(&children); !problem.empty()) return problem;
    stack.push_back({depth, children});
  }
  if (read != nodes) {
    return "the header declares " + std::to_string(nodes) + " nodes, the tree holds " +
           std::to_string(read);
  }
  return {};
}

}  // namespace

std::string SerializeOt(const octomap::OcTree& tree) {
  std::ostringstream out(std::ios::binary);
  tree.write(out);
  return out.str();
}

namespace {

// What a node is in the binary format once the thresholds classify it.
enum class Binary { kUnknown, kFree, kOccupied, kInner };

// writeBinaryNode's encoding of `node` (its children's two bits each, then their subtrees),
// with the leaves t calls unknown and the subtrees holding nothing else left out; *nodes
// counts the nodes a reader creates for the children.
Binary Encode(const octomap::OcTree& tree, const octomap::OcTreeNode* node,
              const StateThresholds& t, std::string* out, std::size_t* nodes) {
  if (!tree.nodeHasChildren(node)) {
    switch (StateOf(node->getOccupancy(), t)) {
      case fusion::v1::VOXEL_STATE_OCCUPIED: return Binary::kOccupied;
      case fusion::v1::VOXEL_STATE_FREE: return Binary::kFree;
      default: return Binary::kUnknown;
    }
  }
  unsigned char bits[2] = {0, 0};
  std::string subtrees;
  for (unsigned i = 0; i < 8; ++i) {
    if (!tree.nodeChildExists(node, i)) continue;
    const Binary b = Encode(tree, tree.getNodeChild(node, i), t, &subtrees, nodes);
    if (b == Binary::kUnknown) continue;
    ++*nodes;
    const unsigned shift = (i % 4) * 2;  // bit i*2 is "free or inner", bit i*2+1 "occupied or inner"
    bits[i / 4] |= static_cast<unsigned char>(
        (b == Binary::kOccupied ? 0u : 1u) << shift | (b == Binary::kFree ? 0u : 2u) << shift);
  }
  if (bits[0] == 0 && bits[1] == 0) return Binary::kUnknown;
  out->push_back(static_cast<char>(bits[0]));
  out->push_back(static_cast<char>(bits[1]));
  *out += subtrees;
  return Binary::kInner;
}

}  // namespace

std::string MaximumLikelihoodData(const octomap::OcTree& tree, const StateThresholds& t,
                                  std::size_t* nodes) {
  std::string data;
  *nodes = 0;
  const octomap::OcTreeNode* root = tree.getRoot();
  if (root == nullptr) return data;
  if (Encode(tree, root, t, &data, nodes) == Binary::kInner) ++*nodes;  // the root itself
  return data;
}

std::string SerializeBt(const octomap::OcTree& tree, const StateThresholds& t) {
  std::size_t nodes = 0;
  const std::string data = MaximumLikelihoodData(tree, t, &nodes);
  // OctoMap's own header (writeBinaryConst of an empty tree of the resolution), its size ours.
  std::ostringstream header(std::ios::binary);
  octomap::OcTree(tree.getResolution()).writeBinaryConst(header);
  std::string out = header.str();
  const std::size_t at = out.find("\nsize 0\n");
  if (at == std::string::npos) throw std::runtime_error("unexpected .bt header from OctoMap");
  out.replace(at, 8, "\nsize " + std::to_string(nodes) + "\n");
  return out + data;
}

Status WriteSnapshotFile(const octomap::OcTree& tree, const std::string& path,
                         std::uint64_t* bytes) {
  const std::string data = SerializeOt(tree);
  const std::string temp = path + ".tmp-" + std::to_string(::getpid());
  const int fd = ::open(temp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) return Status::Error(Errno("open " + temp));
  const bool written = WriteAll(fd, data);
  const bool synced = written && ::fsync(fd) == 0;
  const int saved_errno = errno;
  ::close(fd);
  if (!written || !synced) {
    errno = saved_errno;
    const Status failed = Status::Error(Errno(std::string(written ? "fsync " : "write ") + temp));
    ::unlink(temp.c_str());
    return failed;
  }
  if (::rename(temp.c_str(), path.c_str()) != 0) {
    const Status failed = Status::Error(Errno("rename " + temp + " -> " + path));
    ::unlink(temp.c_str());
    return failed;
  }
  // The rename itself must reach the disk too.
  const int dir = ::open(DirectoryOf(path).c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (dir >= 0) {
    ::fsync(dir);
    ::close(dir);
  }
  if (bytes != nullptr) *bytes = data.size();
  return Status::Ok();
}

std::vector<std::string> RemoveStaleTempFiles(const std::string& path) {
  std::vector<std::string> removed;
  const std::filesystem::path target(path);
  const std::string prefix = target.filename().string() + ".tmp-";
  std::error_code ec;
  const std::filesystem::path dir = target.has_parent_path() ? target.parent_path() : ".";
  for (const auto& entry : std::filesystem::directory_iterator(dir, ec)) {
    const std::string name = entry.path().filename().string();
    if (name.rfind(prefix, 0) != 0) continue;
    const std::string digits = name.substr(prefix.size());
    if (digits.empty() || digits.size() > 9 ||
        digits.find_first_not_of("0123456789") != std::string::npos) {
      continue;
    }
    const auto pid = static_cast<pid_t>(std::stol(digits));
    // A writer that still runs (kill(pid, 0) succeeds or is not allowed) keeps its file.
    if (pid == ::getpid() || ::kill(pid, 0) == 0 || errno != ESRCH) continue;
    if (std::filesystem::remove(entry.path(), ec)) removed.push_back(entry.path().string());
  }
  return removed;
}

LoadStatus LoadSnapshotFile(const std::string& path, double expected_resolution_m,
                            std::unique_ptr<octomap::OcTree>* tree, std::string* message) {
  std::ifstream in(path, std::ios::binary);
  if (!in) {
    if (::access(path.c_str(), F_OK) != 0 && errno == ENOENT) return LoadStatus::kMissing;
    *message = Errno("cannot read " + path);
    return LoadStatus::kError;
  }
  std::string problem;
  std::string id;
  std::uint64_t size = 0;
  double res = 0.0;
  if (!ParseHeader(in, &id, &size, &res)) {
    problem = "not an OctoMap .ot file (bad header)";
  } else if (id != "OcTree") {
    problem = "holds a '" + id + "', not an OcTree";
  } else if (!(res > 0.0)) {
    problem = "invalid resolution in header";
  } else {
    // Every node of an OcTree .ot is 4 bytes of log-odds plus 1 byte of child flags.
    const auto data_start = in.tellg();
    in.seekg(0, std::ios::end);
    const auto data_bytes = static_cast<std::uint64_t>(in.tellg() - data_start);
    if (data_bytes != 5 * size) {
      problem = "header declares " + std::to_string(size) + " nodes (" + std::to_string(5 * size) +
                " bytes) but " + std::to_string(data_bytes) +
                " bytes follow (truncated or damaged)";
    } else if (std::string data(data_bytes, '\0');
               !in.seekg(data_start).read(data.data(), static_cast<std::streamsize>(data_bytes))) {
      problem = "cannot read its node data";
    } else if (const std::string structure = CheckOtNodes(data, size); !structure.empty()) {
      problem = "not a valid octree: " + structure;
    } else {
      // OctoMap reads exactly the bytes checked above. Its own header parser
      // (AbstractOcTree::read) is token based and may end the header elsewhere: for it
      // "res 0.05 data" ends the header, here it does not, so it read bytes never checked (a
      // chain in the comment line after it overflowed the stack again; tests/fuzz snapshot).
      auto octree = std::make_unique<octomap::OcTree>(res);
      in.seekg(data_start);
      if (size > 0) octree->readData(in);
      if (!in || octree->size() != size) {
        problem = "OctoMap could not parse the node data";
      } else {
        *tree = std::move(octree);
      }
    }
  }
  if (!problem.empty()) {
    const std::string aside = path + ".corrupt-" + UtcStamp();
    if (::rename(path.c_str(), aside.c_str()) != 0) {
      *message = path + ": " + problem + "; and it cannot be set aside: " + Errno("rename");
      return LoadStatus::kError;
    }
    *message = path + ": " + problem + "; moved to " + aside;
    return LoadStatus::kCorrupt;
  }
  if (std::abs((*tree)->getResolution() - expected_resolution_m) > 1e-9) {
    *message = path + ": resolution " + std::to_string((*tree)->getResolution()) +
               " m differs from map.resolution_m " + std::to_string(expected_resolution_m) +
               " m; move the file away or configure its resolution";
    tree->reset();
    return LoadStatus::kError;
  }
  return LoadStatus::kLoaded;
}

}  // namespace fusion::service
