// libFuzzer target ros2_cdr: fusion::fuzz::RunRos2Cdr (tests/fuzz/fuzz_entries.h).
#include <cstdio>
#include <cstdlib>

#include "fuzz_entries.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const fusion::fuzz::Outcome outcome = fusion::fuzz::RunRos2Cdr(data, size);
  if (outcome.verdict == fusion::fuzz::Verdict::kBroken) {
    std::fprintf(stderr, "fuzz_ros2_cdr: %s\n", outcome.message.c_str());
    std::abort();
  }
  return 0;
}
