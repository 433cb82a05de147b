// Helpers shared by the fuzz entries: verdicts and a per-process scratch directory for the
// parsers that only read files.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>

#include "fuzz_entries.h"

namespace fusion::fuzz {

inline Outcome Accepted() { return {Verdict::kAccepted, {}}; }
inline Outcome Broken(std::string what) { return {Verdict::kBroken, std::move(what)}; }
// A refusal must say why; an empty message is itself a defect.
inline Outcome Rejected(std::string message) {
  if (message.empty()) return Broken("refused without an error message");
  return {Verdict::kRejected, std::move(message)};
}

// Mutated inputs rarely keep a checksum right, and a parser that stops at a CRC mismatch hides
// everything behind it. These recompute the CRC-32 of every frame that fits in `bytes`:
// recording frames (u32 length, u32 crc of the payload, payload) and PNG chunks after the
// signature (u32 big-endian length, type, data, crc of type and data).
void FixRecordingCrcs(std::string* bytes);
void FixPngCrcs(std::string* bytes, std::size_t png_start);

// <TMPDIR or /tmp>/fusion-fuzz-<pid>-XXXXXX, created on first use and removed at exit.
const std::string& ScratchDir();
// Writes the bytes to ScratchDir()/name (replacing it) and returns the path ("" on failure).
std::string WriteScratch(const std::string& name, const void* data, std::size_t size);
// Removes everything inside ScratchDir() (the directory stays).
void ClearScratch();

}  // namespace fusion::fuzz
