// fusiond's configuration file: LoadConfigFile over the defaults, as main.cc loads --config.
// A configuration it accepts must also convert into core types without an error.
#include "fusion/service/config.h"

#include <string>

#include "common.h"
#include "fusion/service/conversions.h"

namespace fusion::fuzz {
namespace {

Outcome CheckAccepted(const fusion::v1::ServiceConfig& config) {
  for (int i = 0; i < config.sensors_size(); ++i) {
    if (const auto setup = service::SensorSetupFromConfig(config.sensors(i)); !setup.ok()) {
      return Broken("accepted sensors[" + std::to_string(i) +
                    "] does not convert: " + setup.status().message());
    }
  }
  if (const auto options = service::WorldMapOptionsFromConfig(config.map()); !options.ok()) {
    return Broken("accepted map does not convert: " + options.status().message());
  }
  if (const Status valid = service::ValidateConfig(config); !valid.ok()) {
    return Broken("not valid twice: " + valid.message());
  }
  return Accepted();
}

Outcome RunConfig(const std::uint8_t* data, std::size_t size, const char* name) {
  const std::string path = WriteScratch(name, data, size);
  if (path.empty()) return Broken("cannot write the scratch file");
  auto config = service::DefaultConfig();
  if (const Status loaded = service::LoadConfigFile(path, &config); !loaded.ok()) {
    return Rejected(loaded.message());
  }
  return CheckAccepted(config);
}

}  // namespace

Outcome RunConfigText(const std::uint8_t* data, std::size_t size) {
  return RunConfig(data, size, "fusiond.pbtxt");
}

Outcome RunConfigJson(const std::uint8_t* data, std::size_t size) {
  return RunConfig(data, size, "fusiond.json");
}

}  // namespace fusion::fuzz
