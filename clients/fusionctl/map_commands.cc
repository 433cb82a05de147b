// fusionctl snapshot, render and watch: the map's contents, whole or as a stream of changes.
#include <octomap/AbstractOcTree.h>
#include <octomap/OcTree.h>
#include <unistd.h>

#include <cctype>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <sstream>

#include "fusionctl.h"
#include "map_render.h"

namespace fusionctl {
namespace {

// Fetches the whole snapshot; *version receives the map version.
bool FetchSnapshot(Context& ctx, fusion::v1::GetSnapshotRequest::Format format, std::string* bytes,
                   unsigned long long* version, int* rc) {
  grpc::ClientContext context;
  PrepareCall(ctx, &context, ctx.timeout_s);
  fusion::v1::GetSnapshotRequest request;
  request.set_format(format);
  auto reader = ctx.stub->GetSnapshot(&context, request);
  fusion::v1::SnapshotChunk chunk;
  while (reader->Read(&chunk)) {
    if (chunk.offset() != bytes->size()) {
      *rc = fusion::clients::Fail(kTool, "snapshot chunk out of order");
      context.TryCancel();
      return false;
    }
    bytes->append(chunk.data());
    *version = chunk.map_version();
    if (chunk.total_bytes() > 0 && isatty(2)) {
      std::fprintf(stderr, "\rsnapshot: %zu / %llu bytes", bytes->size(),
                   (unsigned long long)chunk.total_bytes());
    }
  }
  if (isatty(2)) std::fprintf(stderr, "\n");
  const auto status = reader->Finish();
  if (!status.ok()) {
    *rc = Failed(ctx, status);
    return false;
  }
  return true;
}

// Whether `path` ends in `extension` (".png"), in any case.
bool HasExtension(const std::string& path, const std::string& extension) {
  if (path.size() <= extension.size()) return false;
  for (std::size_t i = 0; i < extension.size(); ++i) {
    const char c = path[path.size() - extension.size() + i];
    if (std::tolower(static_cast<unsigned char>(c)) != extension[i]) return false;
  }
  return true;
}

}  // namespace

int Snapshot(Context& ctx, const Args& args) {
  if (args.positional.size() != 1) return Usage("snapshot needs FILE.bt or FILE.ot");
  const std::string& path = args.positional[0];
  const bool bt = HasExtension(path, ".bt");
  const bool ot = HasExtension(path, ".ot");
  if (!bt && !ot) return Usage("snapshot file must end in .bt or .ot");
  std::string bytes;
  unsigned long long version = 0;
  int rc = 0;
  if (!FetchSnapshot(ctx,
                     bt ? fusion::v1::GetSnapshotRequest::FORMAT_BT
                        : fusion::v1::GetSnapshotRequest::FORMAT_OT,
                     &bytes, &version, &rc)) {
    return rc;
  }
  std::ofstream out(path, std::ios::binary);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  if (!out.flush()) {
    return fusion::clients::Fail(kTool, "cannot write '" + path + "'");
  }
  if (ctx.json) {
    PrintJsonFields({{"path", path}, {"format", bt ? "bt" : "ot"}},
                    {{"bytes", static_cast<double>(bytes.size())},
                     {"map_version", static_cast<double>(version)}});
  } else {
    std::printf("wrote %s: %zu bytes, map version %llu\n", path.c_str(), bytes.size(), version);
  }
  return fusion::clients::kExitOk;
}

int Render(Context& ctx, const Args& args) {
  if (args.positional.size() != 1) return Usage("render needs FILE.png");
  // The renderer writes PNG only: x.jpg would hold PNG bytes under a JPEG name.
  if (!HasExtension(args.positional[0], ".png")) {
    return Usage("render writes PNG only: the file must end in .png, not '" + args.positional[0] +
                 "'");
  }
  fusion::render::RenderOptions options;
  const std::string color = args.Get("--color", "height");
  if (color == "height")
    options.color_by = fusion::render::ColorBy::kHeight;
  else if (color == "probability")
    options.color_by = fusion::render::ColorBy::kProbability;
  else
    return Usage("--color takes height or probability");
  if (!args.Get("--azimuth").empty() &&
      !fusion::clients::ParseFinite(args.Get("--azimuth"), &options.view_azimuth_deg)) {
    return Usage("bad --azimuth");
  }
  if (!args.Get("--elevation").empty() &&
      !fusion::clients::ParseFinite(args.Get("--elevation"), &options.view_elevation_deg)) {
    return Usage("bad --elevation");
  }
  if (!args.Get("--min-probability").empty() &&
      !fusion::clients::ParseFinite(args.Get("--min-probability"), &options.min_probability)) {
    return Usage("bad --min-probability");
  }
  const std::string size = args.Get("--size");
  int size_chars = 0;  // the whole value must be WxH: "64x48px" is a typo, not 64x48
  if (!size.empty() && (std::sscanf(size.c_str(), "%dx%d%n", &options.width_px, &options.height_px,
                                    &size_chars) != 2 ||
                        size_chars != static_cast<int>(size.size()))) {
    return Usage("--size takes WxH");
  }
  if (options.width_px <= 0 || options.height_px <= 0 || options.width_px > 8192 ||
      options.height_px > 8192) {
    return Usage("--size must be between 1x1 and 8192x8192");
  }
  std::string bytes;
  unsigned long long version = 0;
  int rc = 0;
  if (!FetchSnapshot(ctx, fusion::v1::GetSnapshotRequest::FORMAT_OT, &bytes, &version, &rc)) {
    return rc;
  }
  std::istringstream in(bytes);
  std::unique_ptr<octomap::AbstractOcTree> tree(octomap::AbstractOcTree::read(in));
  auto* octree = dynamic_cast<octomap::OcTree*>(tree.get());
  if (!octree) {
    return fusion::clients::Fail(kTool, "the snapshot is not an OcTree");
  }
  const auto image = fusion::render::RenderOccupied(*octree, options);
  std::string error;
  if (!fusion::render::WritePng(args.positional[0], image, &error)) {
    return fusion::clients::Fail(kTool, error);
  }
  if (ctx.json) {
    PrintJsonFields({{"path", args.positional[0]}},
                    {{"width_px", image.width},
                     {"height_px", image.height},
                     {"voxels_drawn", static_cast<double>(image.voxels_drawn)},
                     {"map_version", static_cast<double>(version)}});
  } else {
    std::printf("wrote %s: %dx%d, %zu occupied voxels drawn, map version %llu\n",
                args.positional[0].c_str(), image.width, image.height, image.voxels_drawn, version);
  }
  return fusion::clients::kExitOk;
}

int Watch(Context& ctx, const Args& args) {
  fusion::v1::StreamUpdatesRequest request;
  unsigned long long since = 0, count = 0;
  if (!OptionUint(args, "--since", 0, &since)) return Usage("--since takes a map version");
  if (!OptionUint(args, "--count", 0, &count)) return Usage("--count takes a count of versions");
  request.set_since_version(since);
  const bool versions_only = args.Has("--versions-only");
  request.set_versions_only(versions_only);
  grpc::ClientContext context;
  PrepareCall(ctx, &context, ctx.timeout_s);  // none unless --timeout
  auto reader = ctx.stub->StreamUpdates(&context, request);
  fusion::v1::MapUpdate update;
  unsigned long long versions = 0;
  std::size_t voxels = 0;
  while (reader->Read(&update)) {
    voxels += static_cast<std::size_t>(update.voxels_size());
    if (ctx.json) PrintJson(update);  // every message: a version may span several
    if (!update.complete()) continue;
    if (ctx.json) {
      // printed above
    } else if (versions_only) {
      std::printf("version %llu (from %llu)\n", (unsigned long long)update.map_version(),
                  (unsigned long long)update.from_version());
    } else {
      std::printf("version %llu (from %llu)%s: %zu voxels changed\n",
                  (unsigned long long)update.map_version(),
                  (unsigned long long)update.from_version(), update.full() ? " full" : "", voxels);
    }
    std::fflush(stdout);
    voxels = 0;
    if (count > 0 && ++versions >= count) {
      context.TryCancel();
      break;
    }
  }
  const auto status = reader->Finish();
  if (!status.ok() && status.error_code() != grpc::StatusCode::CANCELLED) {
    return Failed(ctx, status);
  }
  return fusion::clients::kExitOk;
}

}  // namespace fusionctl
