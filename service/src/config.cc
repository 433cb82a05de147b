#include "fusion/service/config.h"

#include <arpa/inet.h>
#include <google/protobuf/io/tokenizer.h>
#include <google/protobuf/text_format.h>
#include <google/protobuf/util/json_util.h>

#include <cmath>
#include <fstream>
#include <set>
#include <sstream>

#include "fusion/core/fusion_rules.h"
#include "fusion/core/world_map.h"
#include "fusion/service/conversions.h"
#include "fusion/service/ros2_ingest.h"
#include "fusion/service/ros2_output.h"
#include "fusion/service/security.h"

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
  return s.size() >= suffix.size() &&
         s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

Status Fail(const std::string& field, const std::string& message) {
  return Status::Error(field + ": " + message);
}

Status ValidateSensors(const fusion::v1::ServiceConfig& config) {
  std::set<std::string> ids;
  for (int i = 0; i < config.sensors_size(); ++i) {
    const auto& sensor = config.sensors(i);
    const std::string field = "sensors[" + std::to_string(i) + "]";
    if (const auto setup = SensorSetupFromConfig(sensor); !setup.ok()) {
      return Status::Error(field + "." + setup.status().message());
    }
    if (!ids.insert(sensor.id()).second) {
      return Fail(field + ".id", "'" + sensor.id() + "' appears twice");
    }
  }
  return Status::Ok();
}

Status ValidateMap(const fusion::v1::MapConfig& map) {
  if (const auto options = WorldMapOptionsFromConfig(map); !options.ok()) {
    return Status::Error("map." + options.status().message());
  }
  if (map.render_interval_ms() == 0 || map.render_interval_ms() > 600'000) {
    return Fail("map.render_interval_ms",
                std::to_string(map.render_interval_ms()) + " is outside 1..600000");
  }
  // occupied_threshold is core's WorldMapOptions::occupancy_threshold, checked above; the free
  // threshold is the service's alone (StateThresholds).
  if (!(map.free_threshold() > 0.0) || map.free_threshold() > map.occupied_threshold()) {
    return Fail("map.free_threshold", "must lie in (0, occupied_threshold]");
  }
  return Status::Ok();
}

// A beam's cells (r_max_m / map.beam_cell_size_m): core keeps a few tables of that length per
// sensor, so the count is bounded (2 km at the default 2 mm cells).
constexpr double kMaxCellsPerBeam = 1e6;

Status ValidateBeamLengths(const fusion::v1::ServiceConfig& config) {
  const double cell_m = config.map().beam_cell_size_m();
  for (int i = 0; i < config.sensors_size(); ++i) {
    const auto setup = SensorSetupFromConfig(config.sensors(i));
    if (!setup.ok()) continue;  // reported by ValidateSensors
    const double cells = setup->spec.r_max_m / cell_m;
    if (!(cells <= kMaxCellsPerBeam)) {
      std::ostringstream message;
      message << setup->spec.r_max_m << " m in beam cells of " << cell_m
              << " m (map.beam_cell_size_m) is " << cells
              << " cells, more than 1000000: lower r_max_m or raise map.beam_cell_size_m";
      return Fail("sensors[" + std::to_string(i) + "].r_max_m", message.str());
    }
  }
  return Status::Ok();
}

Status ValidateIngest(const fusion::v1::IngestConfig& ingest) {
  if (ingest.reliability() != "best_effort" && ingest.reliability() != "reliable") {
    return Fail("ingest.reliability",
                "'" + ingest.reliability() + "' is not best_effort or reliable");
  }
  if (ingest.max_points() == 0 || ingest.max_points() > 50'000'000) {
    return Fail("ingest.max_points", "must lie in 1..50000000");
  }
  if (!(ingest.quaternion_tolerance() > 0.0 && ingest.quaternion_tolerance() < 0.5)) {
    return Fail("ingest.quaternion_tolerance", "must lie in (0, 0.5)");
  }
  if (!(ingest.max_abs_translation_m() > 0.0 && std::isfinite(ingest.max_abs_translation_m()))) {
    return Fail("ingest.max_abs_translation_m", "must be positive and finite");
  }
  if (ingest.max_queued_mb() < 16 || ingest.max_queued_mb() > 65536) {
    return Fail("ingest.max_queued_mb", "must lie in 16..65536");
  }
  return Status::Ok();
}

Status ValidateLimits(const fusion::v1::QueryLimits& limits) {
  if (limits.max_points_per_query() == 0) {
    return Fail("limits.max_points_per_query", "must be positive");
  }
  // A page of voxels is one gRPC message: 50000 voxels (~55 bytes each) stay under the 4 MB
  // that gRPC clients accept by default.
  if (limits.max_voxels_per_page() == 0 || limits.max_voxels_per_page() > 50'000) {
    return Fail("limits.max_voxels_per_page",
                "must lie in 1..50000 (a page is one gRPC message, at most 4 MB)");
  }
  if (limits.max_box_voxels() == 0) return Fail("limits.max_box_voxels", "must be positive");
  if (limits.max_update_streams() == 0 || limits.max_update_streams() > 10'000) {
    return Fail("limits.max_update_streams", "must lie in 1..10000");
  }
  if (limits.max_plane_cells() < 100'000 || limits.max_plane_cells() > 10'000'000'000ull) {
    return Fail("limits.max_plane_cells", "must lie in 100000..10000000000");
  }
  if (limits.max_heavy_queries() == 0 || limits.max_heavy_queries() > 64) {
    return Fail("limits.max_heavy_queries", "must lie in 1..64");
  }
  if (limits.heavy_query_nice() < 11 || limits.heavy_query_nice() > 19) {
    return Fail("limits.heavy_query_nice",
                "must lie in 11..19 (above the fusion worker's nice value, 10)");
  }
  if (limits.snapshot_chunk_bytes() < 1024 || limits.snapshot_chunk_bytes() > (3u << 20)) {
    return Fail("limits.snapshot_chunk_bytes",
                "must lie in 1024..3145728 (gRPC's default message limit is 4 MiB)");
  }
  return Status::Ok();
}

// The metrics endpoint's address: empty (off), "IPv4:port" or "[IPv6]:port" with a numeric
// address (the HTTP server does not resolve names) and a port in 0..65535 (0: the OS chooses).
Status ValidateMetrics(const fusion::v1::MetricsConfig& metrics) {
  const std::string& address = metrics.listen_address();
  if (address.empty()) return Status::Ok();
  const auto colon = address.rfind(':');
  const std::string port = colon == std::string::npos ? "" : address.substr(colon + 1);
  std::string host = colon == std::string::npos ? address : address.substr(0, colon);
  const bool v6 = host.size() > 2 && host.front() == '[' && host.back() == ']';
  if (v6) host = host.substr(1, host.size() - 2);
  unsigned char parsed[16];
  const bool host_ok = inet_pton(v6 ? AF_INET6 : AF_INET, host.c_str(), parsed) == 1;
  const bool port_ok = !port.empty() && port.size() <= 5 &&
                       port.find_first_not_of("0123456789") == std::string::npos &&
                       std::stoul(port) <= 65535;
  if (!host_ok || !port_ok) {
    return Fail("metrics.listen_address",
                "'" + address + "' is not IPv4:port or [IPv6]:port (numeric, port 0..65535)");
  }
  return Status::Ok();
}

// fusiond's deployed map defaults, where they differ from core's on purpose. The one place for
// them: every other map default in DefaultConfig() is core's own constant.
// - Voxels of 5 cm (core's WorldMapOptions: 2 cm): a service maps rooms to buildings while its
//   sensors move, and a 5 cm render of an SR-3000 frame costs a fraction of a 2 cm one
//   (BENCHMARKS.md); its keys reach +-1638 m (2 cm: +-655 m).
// - Beam cells of 2 mm (core's BeamGridOptions: 1 mm): half the cells, memory and integration
//   work per beam, still 25 cells to a voxel.
// - A dead band around core's single threshold of 0.5: voxels the renderer wrote with next to
//   no evidence stay unknown.
constexpr double kServiceResolutionM = 0.05;
constexpr double kServiceBeamCellSizeM = 0.002;
constexpr double kServiceOccupiedThreshold = 0.55;
constexpr double kServiceFreeThreshold = 0.45;

}  // namespace

fusion::v1::ServiceConfig DefaultConfig() {
  fusion::v1::ServiceConfig config;
  config.set_listen_address("127.0.0.1:0");
  config.set_dds_domain(0);
  config.set_dds_topic("fusion/points");
  config.set_log_level("info");
  config.set_log_format("text");
  auto* map = config.mutable_map();
  map->set_resolution_m(kServiceResolutionM);
  map->set_fusion_rule(FusionRuleName(WorldMapOptions::kDefaultRule));
  map->set_pose_tolerance_m(WorldMapOptions::kDefaultPoseToleranceM);
  map->set_pose_tolerance_deg(WorldMapOptions::kDefaultPoseToleranceDeg);
  map->set_render_interval_ms(10);
  map->set_occupied_threshold(kServiceOccupiedThreshold);
  map->set_free_threshold(kServiceFreeThreshold);
  map->set_beam_cell_size_m(kServiceBeamCellSizeM);
  map->set_change_detection_run(BeamGridOptions::kDefaultChangeRun);
  map->set_change_detection_min_mass(BeamGridOptions::kDefaultChangeMinMass);
  map->set_history_clamping_max(WorldMapOptions::kDefaultHistoryClampingMax);
  map->set_forget_half_life_s(WorldMapOptions::kDefaultForgetHalfLifeS);
  map->set_beam_prior_length_m(WorldMapOptions::kDefaultBeamPriorLengthM);
  auto* ingest = config.mutable_ingest();
  ingest->set_reliability("best_effort");
  ingest->set_max_points(4'000'000);
  ingest->set_quaternion_tolerance(1e-3);
  ingest->set_max_abs_translation_m(1e5);
  ingest->set_max_queued_mb(256);
  config.mutable_persistence()->set_interval_s(30);
  config.mutable_ros2()->set_map_frame("map");
  config.mutable_ros2()->set_tf_history_s(Ros2IngestOptions::kDefaultTfHistoryS);
  auto* limits = config.mutable_limits();
  limits->set_max_points_per_query(100'000);
  limits->set_max_update_streams(64);
  limits->set_max_plane_cells(32'000'000);
  limits->set_max_heavy_queries(4);
  limits->set_heavy_query_nice(13);
  limits->set_max_voxels_per_page(10'000);
  limits->set_max_box_voxels(100'000'000);
  limits->set_snapshot_chunk_bytes(1 << 20);
  return config;
}

Status LoadConfigFile(const std::string& path, fusion::v1::ServiceConfig* config) {
  std::ifstream in(path);
  if (!in) {
    return Status::Error("cannot open configuration file '" + path + "'");
  }
  std::stringstream buffer;
  buffer << in.rdbuf();
  fusion::v1::ServiceConfig loaded;
  if (EndsWith(path, ".json")) {
    const auto status = google::protobuf::util::JsonStringToMessage(buffer.str(), &loaded);
    if (!status.ok()) {
      return Status::Error(path + ": " + std::string(status.message()));
    }
  } else {
    google::protobuf::TextFormat::Parser parser;
    ErrorCollector collector;
    parser.RecordErrorsTo(&collector);
    if (!parser.ParseFromString(buffer.str(), &loaded)) {
      return Status::Error(path + ": " + collector.text());
    }
  }
  config->MergeFrom(loaded);
  return ValidateConfig(*config);
}

Status ValidateConfig(const fusion::v1::ServiceConfig& config) {
  if (config.listen_address().find(':') == std::string::npos) {
    return Status::Error("listen_address: '" + config.listen_address() + "' is not host:port");
  }
  // Cyclone DDS domain ids are 0..230 (the port mapping runs out above that).
  if (config.dds_domain() > 230) {
    return Status::Error("dds_domain: " + std::to_string(config.dds_domain()) + " is outside 0..230");
  }
  if (config.dds_topic().empty()) {
    return Status::Error("dds_topic: must not be empty");
  }
  static const char* const kLevels[] = {"trace", "debug",    "info", "warn",
                                        "error", "critical", "off"};
  bool level_ok = false;
  for (const char* level : kLevels) level_ok = level_ok || config.log_level() == level;
  if (!level_ok) {
    return Status::Error("log_level: '" + config.log_level() +
             "' is not one of trace, debug, info, warn, error, critical, off");
  }
  if (!config.log_format().empty() && config.log_format() != "text" &&
      config.log_format() != "json") {
    return Status::Error("log_format: '" + config.log_format() + "' is not text or json");
  }
  for (const Status& part :
       {ValidateSensors(config), ValidateMap(config.map()), ValidateBeamLengths(config),
        ValidateIngest(config.ingest()), ValidateLimits(config.limits()),
        ValidateSecurity(config.security()), ValidateMetrics(config.metrics())}) {
    if (!part.ok()) return part;
  }
  // The ROS 2 section: its output's fields, and (read by them) the ingest's.
  if (const auto ros2 = Ros2OutputOptionsFromConfig(config); !ros2.ok()) return ros2.status();
  return Status::Ok();
}

Status ParseSensorFlag(const std::string& value, fusion::v1::SensorConfig* sensor) {
  const auto eq = value.find('=');
  if (eq == std::string::npos || eq == 0 || eq + 1 == value.size()) {
    return Status::Error("--sensor: '" + value + "' is not ID=PRESET");
  }
  sensor->set_id(value.substr(0, eq));
  sensor->set_preset(value.substr(eq + 1));
  return Status::Ok();
}

}  // namespace fusion::service
