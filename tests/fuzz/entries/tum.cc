// TUM RGB-D: groundtruth.txt, a NUL byte, then the depth PNG, through ImportTum. The PNG is
// stored under the name the first frame line gives (depth/<stamp>.png), so that stamps and
// poses vary with the input; inputs naming ".." are refused (no file outside the scratch
// directory is ever read). The PNG's chunk CRCs are recomputed (FixPngCrcs): libpng refuses a
// mutated header otherwise, and its width and height are what ReadPng16 must not trust.
#include <sys/stat.h>

#include <cctype>
#include <sstream>

#include "cloud_checks.h"
#include "fusion/clients/importers.h"

namespace fusion::fuzz {
namespace {

constexpr std::uint64_t kMaxFrames = 4;  // every line re-reads the PNG: bound the work

// The first frame's file if it is a plain "depth/NAME.png" (NAME of letters, digits, "._-",
// not starting with '.'), else "".
std::string FirstDepthFile(const std::string& groundtruth) {
  std::istringstream lines(groundtruth);
  for (std::string line; std::getline(lines, line);) {
    if (line.empty() || line[0] == '#') continue;
    std::string file;
    std::istringstream(line) >> file;
    const std::string name = file.rfind("depth/", 0) == 0 ? file.substr(6) : "";
    const bool png = name.size() > 4 && name.compare(name.size() - 4, 4, ".png") == 0;
    if (!png || name.size() > 64 || name[0] == '.') return {};
    for (const char c : name) {
      if (!std::isalnum(static_cast<unsigned char>(c)) && c != '.' && c != '_' && c != '-')
        return {};
    }
    return file;
  }
  return {};
}

}  // namespace

Outcome RunTum(const std::uint8_t* data, std::size_t size) {
  std::string input(reinterpret_cast<const char*>(data), size);
  const std::size_t nul = input.find('\0');
  const std::string groundtruth = input.substr(0, nul);
  if (groundtruth.find("..") != std::string::npos) return Rejected("input names '..' (skipped)");
  ClearScratch();  // no PNG of an earlier input may answer for this one
  if (WriteScratch("groundtruth.txt", groundtruth.data(), groundtruth.size()).empty()) {
    return Broken("cannot write the scratch file");
  }
  const std::string png = FirstDepthFile(groundtruth);
  if (!png.empty() && nul != std::string::npos) {
    FixPngCrcs(&input, nul + 1);
    ::mkdir((ScratchDir() + "/depth").c_str(), 0700);
    if (WriteScratch(png, input.data() + nul + 1, size - nul - 1).empty()) {
      return Broken("cannot write the scratch PNG");
    }
  }
  clients::TumOptions options;
  options.directory = ScratchDir();
  options.max_frames = kMaxFrames;
  std::uint64_t frames = 0;
  Outcome broken;
  const fusion::Status s = clients::ImportTum(options, [&](fusion::v1::RecordedCloud&& cloud) {
    ++frames;
    if (Outcome o = CheckShape(cloud); o.verdict == Verdict::kBroken) broken = o;
    if (Outcome o = CheckUnitPose(cloud.t_world_sensor()); o.verdict == Verdict::kBroken)
      broken = o;
    if (cloud.sequence_number() != frames) broken = Broken("sequence numbers do not count frames");
    return fusion::Status::Ok();
  });
  if (broken.verdict == Verdict::kBroken) return broken;
  if (!s.ok()) return Rejected(s.message());
  if (frames == 0 || frames > kMaxFrames)
    return Broken("success with " + std::to_string(frames) + " frames");
  return Accepted();
}

}  // namespace fusion::fuzz
