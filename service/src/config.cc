#include "fusion/service/config.h"

#include <fstream>
#include <sstream>

#include <google/protobuf/io/tokenizer.h>
#include <google/protobuf/text_format.h>
#include <google/protobuf/util/json_util.h>

namespace fusion::service {
namespace {

// Collects text-format parse errors with their line and column.
class ErrorCollector : public google::protobuf::io::ErrorCollector {
 public:
  void AddError(int line, int column, const std::string& message) override {
    if (!text_.empty()) text_ += "; ";
    text_ += "line " + std::to_string(line + 1) + ":" + std::to_string(column + 1) + ": " + message;
  }
  const std::string& text() const { return text_; }

 private:
  std::string text_;
};

bool EndsWith(const std::string& s, const std::string& suffix) {
  return s.size() >= suffix.size() && s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

}  // namespace

fusion::v1::ServiceConfig DefaultConfig() {
  fusion::v1::ServiceConfig config;
  config.set_listen_address("127.0.0.1:0");
  config.set_dds_domain(0);
  config.set_dds_topic("fusion/points");
  config.set_log_level("info");
  return config;
}

bool LoadConfigFile(const std::string& path, fusion::v1::ServiceConfig* config,
                    std::string* error) {
  std::ifstream in(path);
  if (!in) {
    *error = "cannot open configuration file '" + path + "'";
    return false;
  }
  std::stringstream buffer;
  buffer << in.rdbuf();
  fusion::v1::ServiceConfig loaded;
  if (EndsWith(path, ".json")) {
    const auto status = google::protobuf::util::JsonStringToMessage(buffer.str(), &loaded);
    if (!status.ok()) {
      *error = path + ": " + std::string(status.message());
      return false;
    }
  } else {
    google::protobuf::TextFormat::Parser parser;
    ErrorCollector collector;
    parser.RecordErrorsTo(&collector);
    if (!parser.ParseFromString(buffer.str(), &loaded)) {
      *error = path + ": " + collector.text();
      return false;
    }
  }
  config->MergeFrom(loaded);
  return ValidateConfig(*config, error);
}

bool ValidateConfig(const fusion::v1::ServiceConfig& config, std::string* error) {
  if (config.listen_address().find(':') == std::string::npos) {
    *error = "listen_address: '" + config.listen_address() + "' is not host:port";
    return false;
  }
  // Cyclone DDS domain ids are 0..230 (the port mapping runs out above that).
  if (config.dds_domain() > 230) {
    *error = "dds_domain: " + std::to_string(config.dds_domain()) + " is outside 0..230";
    return false;
  }
  if (config.dds_topic().empty()) {
    *error = "dds_topic: must not be empty";
    return false;
  }
  static const char* const kLevels[] = {"trace", "debug", "info", "warn",
                                        "error", "critical", "off"};
  bool level_ok = false;
  for (const char* level : kLevels) level_ok = level_ok || config.log_level() == level;
  if (!level_ok) {
    *error = "log_level: '" + config.log_level() +
             "' is not one of trace, debug, info, warn, error, critical, off";
    return false;
  }
  return true;
}

}  // namespace fusion::service
