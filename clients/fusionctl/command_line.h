// fusionctl's command line: the global options, each command's own options and arity, and
// each command's usage text (command_line.cc).
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "fusionctl.h"

namespace fusionctl {

struct CommandSpec {
  const char* name;
  int (*run)(Context&, const Args&);
  const char* usage;  // `fusionctl COMMAND --help`
  std::vector<std::string> valued_options;
  std::vector<std::string> flags;
  std::size_t min_positional;
  std::size_t max_positional;
  // Deadline of each call without --timeout; 0: none. Planes and snapshots take longer.
  double default_timeout_s;
};

// Every command, in the order of the global usage.
const std::vector<CommandSpec>& Commands();
const char* GlobalUsage();

// Splits argv into the global options (into ctx, with the environment's fallbacks), the
// command and its arguments, strictly: an unknown option, a missing value or a wrong number of
// arguments is a usage error. Returns the exit code when fusionctl is done already (--help, a
// bad command line); otherwise *command is set.
std::optional<int> ParseCommandLine(int argc, char** argv, Context* ctx,
                                    const CommandSpec** command, Args* args);

}  // namespace fusionctl
