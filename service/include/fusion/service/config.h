// fusiond's configuration: defaults, loading from text-format or JSON files, overrides.
#pragma once

#include <string>

#include "fusion/v1/config.pb.h"

namespace fusion::service {

// The configuration a user gets with no file: loopback, OS-chosen port, private domain 0.
[[nodiscard]] fusion::v1::ServiceConfig DefaultConfig();

// Loads a configuration file (".json" as JSON, anything else as protobuf text format) over
// the defaults. Returns false with *error naming the file, line and field on failure.
bool LoadConfigFile(const std::string& path, fusion::v1::ServiceConfig* config,
                    std::string* error);

// Checks every field; returns false with *error naming the offending field.
bool ValidateConfig(const fusion::v1::ServiceConfig& config, std::string* error);

}  // namespace fusion::service
