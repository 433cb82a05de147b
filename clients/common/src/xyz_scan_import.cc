// Plain "x y z" text scans (optionally .bz2), with OctoMap's NODE lines starting new clouds.
#include <fcntl.h>
#include <octomap/math/Pose6D.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <cmath>
#include <cstring>
#include <fstream>
#include <sstream>

#include "fusion/clients/importers.h"

namespace fusion::clients {

namespace {

bool EndsWith(const std::string& s, const std::string& suffix) {
  return s.size() >= suffix.size() &&
         s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

// Reads a whole file, through `bzip2 -dc` when it ends in .bz2.
Status ReadText(const std::string& path, std::string* text) {
  if (!EndsWith(path, ".bz2")) {
    std::ifstream in(path, std::ios::binary);
    if (!in) return Status::Error("cannot open " + path + ": " + std::strerror(errno));
    text->assign((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    return Status::Ok();
  }
  if (access(path.c_str(), R_OK) != 0)
    return Status::Error("cannot open " + path + ": " + std::strerror(errno));
  int pipe_fds[2];
  if (pipe(pipe_fds) != 0) return Status::Error(std::string("pipe: ") + std::strerror(errno));
  const pid_t child = fork();
  if (child < 0) return Status::Error(std::string("fork: ") + std::strerror(errno));
  if (child == 0) {
    dup2(pipe_fds[1], STDOUT_FILENO);
    close(pipe_fds[0]);
    close(pipe_fds[1]);
    execlp("bzip2", "bzip2", "-dc", "--", path.c_str(), static_cast<char*>(nullptr));
    _exit(127);
  }
  close(pipe_fds[1]);
  char buffer[1 << 16];
  for (;;) {
    const ssize_t n = read(pipe_fds[0], buffer, sizeof buffer);
    if (n > 0) text->append(buffer, static_cast<std::size_t>(n));
    if (n == 0 || (n < 0 && errno != EINTR)) break;
  }
  close(pipe_fds[0]);
  int status = 0;
  waitpid(child, &status, 0);
  if (!WIFEXITED(status) || WEXITSTATUS(status) != 0) {
    return Status::Error(path + ": bzip2 -dc failed" +
                         std::string(WIFEXITED(status) && WEXITSTATUS(status) == 127
                                         ? " (bzip2 not installed?)"
                                         : " (corrupt or truncated .bz2?)"));
  }
  return Status::Ok();
}

}  // namespace

Status ReadXyzScan(const std::string& path, const fusion::v1::RecordedPose& pose,
                   std::vector<fusion::v1::RecordedCloud>* clouds) {
  std::string text;
  if (Status s = ReadText(path, &text); !s.ok()) return s;
  clouds->clear();
  fusion::v1::RecordedCloud current;
  *current.mutable_t_world_sensor() = pose;
  bool have_current = false;
  const auto finish = [&]() {
    if (!have_current) return;
    current.set_width(static_cast<std::uint32_t>(current.xyz_f32le().size() / 12));
    current.set_height(1);
    clouds->push_back(std::move(current));
    current.Clear();
  };
  std::size_t pos = 0, line_number = 0;
  while (pos < text.size()) {
    std::size_t eol = text.find('\n', pos);
    if (eol == std::string::npos) eol = text.size();
    const char* p = text.c_str() + pos;
    const char* line_end = text.c_str() + eol;
    pos = eol + 1;
    ++line_number;
    while (p < line_end && (*p == ' ' || *p == '\t' || *p == '\r')) ++p;
    if (p == line_end || *p == '#') continue;
    const std::string where = path + ":" + std::to_string(line_number);
    if (line_end - p >= 4 && std::strncmp(p, "NODE", 4) == 0) {
      finish();
      std::istringstream words(std::string(p + 4, line_end));
      double x, y, z, roll, pitch, yaw;
      if (!(words >> x >> y >> z >> roll >> pitch >> yaw)) {
        return Status::Error(where + ": expected 'NODE x y z roll pitch yaw'");
      }
      const octomath::Pose6D node(x, y, z, roll, pitch, yaw);
      auto* node_pose = current.mutable_t_world_sensor();
      node_pose->set_tx(x);
      node_pose->set_ty(y);
      node_pose->set_tz(z);
      node_pose->set_qw(node.rot().u());
      node_pose->set_qx(node.rot().x());
      node_pose->set_qy(node.rot().y());
      node_pose->set_qz(node.rot().z());
      have_current = true;
      continue;
    }
    double v[3];
    char* end = nullptr;
    const char* q = p;
    for (int a = 0; a < 3; ++a) {
      v[a] = std::strtod(q, &end);
      if (end == q || !std::isfinite(v[a])) {
        return Status::Error(where + ": expected 'x y z' in metres, got '" +
                             std::string(p, line_end) + "'");
      }
      q = end;
    }
    while (q < line_end && (*q == ' ' || *q == '\t' || *q == '\r')) ++q;
    if (q != line_end) {
      return Status::Error(where + ": trailing text after 'x y z': '" + std::string(p, line_end) +
                           "'");
    }
    AppendPoint(static_cast<float>(v[0]), static_cast<float>(v[1]), static_cast<float>(v[2]),
                &current);
    have_current = true;
  }
  finish();
  if (clouds->empty()) return Status::Error(path + ": no points");
  return Status::Ok();
}

}  // namespace fusion::clients
