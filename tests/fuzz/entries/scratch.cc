#include <fcntl.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <vector>

#include "common.h"

namespace fusion::fuzz {
namespace {

struct ScratchOwner {
  std::string dir;
  ScratchOwner() {
    const char* tmp = std::getenv("TMPDIR");
    std::string pattern = std::string(tmp != nullptr && *tmp != '\0' ? tmp : "/tmp") +
                          "/fusion-fuzz-" + std::to_string(::getpid()) + "-XXXXXX";
    std::vector<char> name(pattern.begin(), pattern.end());
    name.push_back('\0');
    if (::mkdtemp(name.data()) != nullptr) dir = name.data();
  }
  ~ScratchOwner() {
    std::error_code ec;
    if (!dir.empty()) std::filesystem::remove_all(dir, ec);
  }
};

}  // namespace

const std::string& ScratchDir() {
  static const ScratchOwner owner;
  return owner.dir;
}

std::string WriteScratch(const std::string& name, const void* data, std::size_t size) {
  if (ScratchDir().empty()) return {};
  const std::string path = ScratchDir() + "/" + name;
  const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_CLOEXEC, 0600);
  if (fd < 0) return {};
  const auto* bytes = static_cast<const char*>(data);
  std::size_t done = 0;
  while (done < size) {
    const ssize_t n = ::write(fd, bytes + done, size - done);
    if (n <= 0) break;
    done += static_cast<std::size_t>(n);
  }
  // Cut to the new length after writing: truncating to zero first makes ext4 flush the file
  // to disk on close (its replace-via-truncate heuristic), ~2 ms per input on /tmp.
  const bool cut = ::ftruncate(fd, static_cast<off_t>(size)) == 0;
  ::close(fd);
  return done == size && cut ? path : std::string();
}

void ClearScratch() {
  std::error_code ec;
  for (const auto& entry : std::filesystem::directory_iterator(ScratchDir(), ec)) {
    std::filesystem::remove_all(entry.path(), ec);
  }
}

}  // namespace fusion::fuzz
