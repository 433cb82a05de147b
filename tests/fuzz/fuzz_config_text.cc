// libFuzzer target config_text: fusion::fuzz::RunConfigText (tests/fuzz/fuzz_entries.h).
#include <cstdio>
#include <cstdlib>

#include "fuzz_entries.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const fusion::fuzz::Outcome outcome = fusion::fuzz::RunConfigText(data, size);
  if (outcome.verdict == fusion::fuzz::Verdict::kBroken) {
    std::fprintf(stderr, "fuzz_config_text: %s\n", outcome.message.c_str());
    std::abort();
  }
  return 0;
}
