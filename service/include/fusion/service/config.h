// fusiond's configuration: defaults, loading from text-format or JSON files, overrides.
#pragma once

#include <string>

#include "fusion/core/status.h"
#include "fusion/v1/config.pb.h"

namespace fusion::service {

// The configuration a user gets with no file: loopback, OS-chosen port, private domain 0,
// no sensors, no persistence.
[[nodiscard]] fusion::v1::ServiceConfig DefaultConfig();

// Loads a configuration file (".json" as JSON, anything else as protobuf text format) over
// the defaults (scalars set in the file replace the defaults, sensors are appended).
// The error names the file, line and field.
[[nodiscard]] Status LoadConfigFile(const std::string& path, fusion::v1::ServiceConfig* config);

// Checks every field; the error names the offending field (e.g. "sensors[1].fov_h_deg: ...").
[[nodiscard]] Status ValidateConfig(const fusion::v1::ServiceConfig& config);

// Parses a "--sensor ID=PRESET" command-line value into a sensor entry.
[[nodiscard]] Status ParseSensorFlag(const std::string& value, fusion::v1::SensorConfig* sensor);

}  // namespace fusion::service
