// Protobuf round trips of the configuration and the errors a bad file gets.
#include <google/protobuf/text_format.h>
#include <google/protobuf/util/json_util.h>
#include <google/protobuf/util/message_differencer.h>
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>

#include "fusion/service/config.h"
#include "fusion/service/conversions.h"

namespace fusion::service {
namespace {

std::string WriteTemp(const std::string& name, const std::string& text) {
  const std::string path = ::testing::TempDir() + name;
  std::ofstream(path) << text;
  return path;
}

TEST(ConfigProtoTest, BinaryTextAndJsonRoundTrip) {
  auto config = DefaultConfig();
  config.set_listen_address("127.0.0.1:6000");
  config.set_dds_domain(17);
  const std::string wire = config.SerializeAsString();
  fusion::v1::ServiceConfig from_wire;
  ASSERT_TRUE(from_wire.ParseFromString(wire));
  EXPECT_TRUE(google::protobuf::util::MessageDifferencer::Equals(config, from_wire));

  std::string text;
  ASSERT_TRUE(google::protobuf::TextFormat::PrintToString(config, &text));
  fusion::v1::ServiceConfig from_text;
  ASSERT_TRUE(google::protobuf::TextFormat::ParseFromString(text, &from_text));
  EXPECT_TRUE(google::protobuf::util::MessageDifferencer::Equals(config, from_text));

  std::string json;
  ASSERT_TRUE(google::protobuf::util::MessageToJsonString(config, &json).ok());
  fusion::v1::ServiceConfig from_json;
  ASSERT_TRUE(google::protobuf::util::JsonStringToMessage(json, &from_json).ok());
  EXPECT_TRUE(google::protobuf::util::MessageDifferencer::Equals(config, from_json));
}

TEST(ConfigProtoTest, FileOverridesDefaults) {
  const auto path = WriteTemp("fusiond_ok.pbtxt", "dds_domain: 42\nlog_level: \"debug\"\n");
  auto config = DefaultConfig();
  fusion::Status status;
  ASSERT_TRUE((status = LoadConfigFile(path, &config)).ok()) << status.message();
  EXPECT_EQ(config.dds_domain(), 42u);
  EXPECT_EQ(config.log_level(), "debug");
  EXPECT_EQ(config.listen_address(), "127.0.0.1:0");  // default kept
}

TEST(ConfigProtoTest, BadFilesAreRefusedWithTheFieldNamed) {
  fusion::Status status;
  auto config = DefaultConfig();
  EXPECT_FALSE((status = LoadConfigFile(WriteTemp("bad1.pbtxt", "dds_domian: 3\n"), &config)).ok());
  EXPECT_NE(status.message().find("dds_domian"), std::string::npos) << status.message();
  EXPECT_NE(status.message().find("line 1"), std::string::npos) << status.message();

  config = DefaultConfig();
  EXPECT_FALSE((status = LoadConfigFile(WriteTemp("bad2.pbtxt", "dds_domain: 999\n"), &config)).ok());
  EXPECT_NE(status.message().find("dds_domain"), std::string::npos) << status.message();

  config = DefaultConfig();
  EXPECT_FALSE((status = LoadConfigFile(WriteTemp("bad3.json", "{\"logLevel\": \"loud\"}"), &config)).ok());
  EXPECT_NE(status.message().find("log_level"), std::string::npos) << status.message();

  EXPECT_FALSE((status = LoadConfigFile("/nonexistent/fusiond.pbtxt", &config)).ok());
  EXPECT_NE(status.message().find("cannot open"), std::string::npos) << status.message();
}

// Each bad field of a configuration is refused with the field's path in the message.
TEST(ConfigProtoTest, SensorMapAndIngestErrorsNameTheirField) {
  const std::pair<const char*, const char*> cases[] = {
      {"sensors { preset: \"sr3000\" }", "sensors[0].id"},
      {"sensors { id: \"a\" preset: \"kinect\" }", "sensors[0].preset"},
      {"sensors { id: \"a\" preset: \"sr3000\" } sensors { id: \"a\" preset: \"stoc\" }",
       "sensors[1].id"},
      {"sensors { id: \"a\" preset: \"sr3000\" fov_h_deg: 0 }", "sensors[0].fov_h_deg"},
      {"sensors { id: \"a\" preset: \"sr3000\" r_max_m: 0.1 }", "sensors[0].r_max_m"},
      // Refused, not an abort in core ("beam too long for the cell size").
      {"sensors { id: \"a\" preset: \"sr3000\" r_max_m: 1e9 }", "sensors[0].r_max_m"},
      {"sensors { id: \"a\" preset: \"sr3000\" r_max_m: 1e39 }", "sensors[0].r_max_m"},
      {"sensors { id: \"a\" preset: \"sr3000\" r_max_m: 2500 }", "sensors[0].r_max_m"},
      {"sensors { id: \"a\" preset: \"sr3000\" cols: 100000 rows: 100000 }", "sensors[0].cols"},
      {"sensors { id: \"a\" r_min_m: 0.1 r_max_m: 5 fov_h_deg: 40 fov_v_deg: 30 cols: 10 }",
       "sensors[0].rows"},
      {"sensors { id: \"a\" preset: \"sr3000\" mount { qw: 2 } }", "sensors[0].mount"},
      {"sensors { id: \"a\" preset: \"sr3000\" model: \"magic\" }", "sensors[0].model"},
      {"sensors { id: \"a\" preset: \"sr3000\" queue_depth: 0 }", "sensors[0].queue_depth"},
      {"sensors { id: \"a\" preset: \"laser_3d\" azimuth_min_deg: -30 }",
       "sensors[0].azimuth_min_deg"},
      {"sensors { id: \"a\" preset: \"sr3000\" beam_prior_length_m: -2 }",
       "sensors[0].beam_prior_length_m"},
      {"sensors { id: \"a\" preset: \"sr3000\" fov_v_deg: 20 elevation_min_deg: -5 "
       "elevation_max_deg: 5 }",
       "sensors[0].fov_v_deg"},
      {"sensors { id: \"a\" preset: \"sr3000\" elevation_min_deg: 10 elevation_max_deg: 95 }",
       "sensors[0].elevation_min_deg"},
      {"sensors { id: \"a\" preset: \"sr3000\" azimuth_min_deg: 100 azimuth_max_deg: 190 }",
       "sensors[0].azimuth_min_deg"},
      {"sensors { id: \"a\" preset: \"sr3000\" pinhole { stride: 2 } }", "sensors[0].pinhole"},
      {"sensors { id: \"a\" preset: \"kinect_v1\" pinhole { stride: 2 } cols: 10 }",
       "sensors[0].pinhole"},
      {"sensors { id: \"a\" preset: \"kinect_v1\" cols: 10 rows: 10 }", "sensors[0].cols"},
      {"sensors { id: \"a\" preset: \"kinect_v1\" pinhole { fx: -1 fy: 500 width: 64 "
       "height: 48 } }",
       "sensors[0].pinhole"},
      {"sensors { id: \"a\" preset: \"kinect_v1\" pinhole { fx: 500 fy: 500 width: 100000 "
       "height: 48 } }",
       "sensors[0].pinhole"},
      {"sensors { id: \"a\" r_min_m: 0.1 r_max_m: 5 q_mu { a1: 1 } q_sigma { a0: 0.01 } }",
       "sensors[0].fov_h_deg"},
      {"map { resolution_m: 100 }", "map.resolution_m"},
      {"map { fusion_rule: \"average\" }", "map.fusion_rule"},
      {"map { pose_tolerance_deg: 500 }", "map.pose_tolerance_deg"},
      {"map { free_threshold: 0.7 occupied_threshold: 0.6 }", "map.free_threshold"},
      {"map { beam_cell_size_m: 5 }", "map.beam_cell_size_m"},
      {"map { max_range_m: -1 }", "map.max_range_m"},
      {"ingest { reliability: \"sometimes\" }", "ingest.reliability"},
      {"ingest { quaternion_tolerance: 0.9 }", "ingest.quaternion_tolerance"},
      {"limits { snapshot_chunk_bytes: 100000000 }", "limits.snapshot_chunk_bytes"},
      {"limits { max_voxels_per_page: 50001 }", "limits.max_voxels_per_page"},
      {"limits { max_update_streams: 10001 }", "limits.max_update_streams"},
      {"limits { max_plane_cells: 1000 }", "limits.max_plane_cells"},
      {"limits { max_heavy_queries: 65 }", "limits.max_heavy_queries"},
      {"limits { heavy_query_nice: 5 }", "limits.heavy_query_nice"},
      {"ingest { max_queued_mb: 8 }", "ingest.max_queued_mb"},
      {"map { change_detection_run: 101 }", "map.change_detection_run"},
      {"map { change_detection_min_mass: 1.5 }", "map.change_detection_min_mass"},
      {"map { history_clamping_max: 1.5 }", "map.history_clamping_max"},
      {"map { history_clamping_max: 0.0005 }", "map.history_clamping_max"},
      {"map { forget_half_life_s: -1 }", "map.forget_half_life_s"},
      {"map { beam_prior_length_m: -1 }", "map.beam_prior_length_m"},
      {"map { beam_prior_length_m: 5000 }", "map.beam_prior_length_m"},
      {"metrics { listen_address: \"localhost:9464\" }", "metrics.listen_address"},
      {"metrics { listen_address: \"127.0.0.1\" }", "metrics.listen_address"},
      {"metrics { listen_address: \"127.0.0.1:65536\" }", "metrics.listen_address"},
      {"metrics { listen_address: \"127.0.0.1:-1\" }", "metrics.listen_address"},
      {"metrics { listen_address: \"127.0.0.1:\" }", "metrics.listen_address"},
      {"metrics { listen_address: \"::1:9464\" }", "metrics.listen_address"},
      {"metrics { listen_address: \"[::1:9464\" }", "metrics.listen_address"},
  };
  for (const auto& [text, field] : cases) {
    auto config = DefaultConfig();
    fusion::Status status;
    EXPECT_FALSE((status = LoadConfigFile(WriteTemp("bad_field.pbtxt", text), &config)).ok()) << text;
    EXPECT_EQ(status.message().rfind(field, 0), 0u) << text << " gave: " << status.message();
  }
}

// Metrics are off by default; an address turns them on (numeric, any port including 0).
TEST(ConfigProtoTest, MetricsAddressIsOptionalAndNumeric) {
  EXPECT_TRUE(DefaultConfig().metrics().listen_address().empty());
  for (const char* address : {"127.0.0.1:9464", "127.0.0.1:0", "0.0.0.0:9464", "[::1]:0"}) {
    auto config = DefaultConfig();
    const fusion::Status status = LoadConfigFile(
        WriteTemp("metrics.pbtxt", std::string("metrics { listen_address: \"") + address + "\" }"),
        &config);
    EXPECT_TRUE(status.ok()) << address << ": " << status.message();
    EXPECT_EQ(config.metrics().listen_address(), address);
  }
}

TEST(ConfigProtoTest, FullExampleLoadsAndSensorsBecomeCoreSpecs) {
  // This file is tests/unit/service/config_proto_test.cc; the example is docs/ at the root.
  const std::string example =
      (std::filesystem::path(__FILE__).parent_path() / "../../../docs/fusiond.example.pbtxt")
          .string();
  auto config = DefaultConfig();
  fusion::Status status;
  ASSERT_TRUE((status = LoadConfigFile(example, &config)).ok()) << status.message();
  ASSERT_EQ(config.sensors_size(), 3);
  auto sr = SensorSetupFromConfig(config.sensors(0));
  ASSERT_TRUE(sr.ok()) << sr.status().message();
  EXPECT_EQ(sr->spec.cols, 176);
  auto custom = SensorSetupFromConfig(config.sensors(2));
  ASSERT_TRUE(custom.ok()) << custom.status().message();
  EXPECT_NEAR(custom->spec.fov_h_rad, 270.0 * M_PI / 180.0, 1e-9);
  EXPECT_EQ(custom->spec.model, ForwardModelKind::kClassicBeam);
  // The stereo camera is mounted 25 mm left of and 80 mm below the SR-3000's frame.
  auto stereo = SensorSetupFromConfig(config.sensors(1));
  ASSERT_TRUE(stereo.ok()) << stereo.status().message();
  EXPECT_NEAR(stereo->T_published_sensor.translation().y(), 0.08, 1e-12);
  auto options = WorldMapOptionsFromConfig(config.map());
  ASSERT_TRUE(options.ok()) << options.status().message();
  EXPECT_EQ(options->rule, FusionRule::kIndependentOpinionPool);
}

// A camera by its intrinsics (or a preset's with another stride) and a scanner by its limits
// become the core specs they describe.
TEST(ConfigProtoTest, PinholeAndAsymmetricSensorsBecomeCoreSpecs) {
  fusion::v1::ServiceConfig config;
  ASSERT_TRUE(google::protobuf::TextFormat::ParseFromString(
      "sensors { id: \"kinect\" preset: \"kinect_v1\" pinhole { stride: 4 } }\n"
      "sensors { id: \"cam\" r_min_m: 0.2 r_max_m: 4 q_mu { a1: 1 } q_sigma { a0: 0.01 }\n"
      "  pinhole { fx: 300 fy: 310 cx: 100.5 cy: 60.25 width: 200 height: 120 } }\n"
      "sensors { id: \"scan\" preset: \"laser_3d\" azimuth_min_deg: -60 azimuth_max_deg: 30\n"
      "  elevation_min_deg: -7 elevation_max_deg: 32 cols: 360 rows: 156 }\n",
      &config));
  auto kinect = SensorSetupFromConfig(config.sensors(0));
  ASSERT_TRUE(kinect.ok()) << kinect.status().message();
  ASSERT_TRUE(kinect->spec.pinhole.has_value());
  EXPECT_EQ(kinect->spec.pinhole->stride, 4);
  EXPECT_DOUBLE_EQ(kinect->spec.pinhole->fx_px, 520.9);
  EXPECT_EQ(kinect->spec.cols, 160);
  EXPECT_EQ(kinect->spec.rows, 120);
  auto cam = SensorSetupFromConfig(config.sensors(1));
  ASSERT_TRUE(cam.ok()) << cam.status().message();
  ASSERT_TRUE(cam->spec.pinhole.has_value());
  EXPECT_DOUBLE_EQ(cam->spec.pinhole->cy_px, 60.25);
  EXPECT_EQ(cam->spec.cols, 200);
  EXPECT_EQ(cam->spec.rows, 120);
  auto scan = SensorSetupFromConfig(config.sensors(2));
  ASSERT_TRUE(scan.ok()) << scan.status().message();
  EXPECT_FALSE(scan->spec.pinhole.has_value());
  EXPECT_NEAR(scan->spec.fov_h_rad, 90.0 * M_PI / 180.0, 1e-12);
  EXPECT_NEAR(scan->spec.azimuth_centre_rad, -15.0 * M_PI / 180.0, 1e-12);
  EXPECT_NEAR(scan->spec.fov_v_rad, 39.0 * M_PI / 180.0, 1e-12);
  EXPECT_NEAR(scan->spec.elevation_centre_rad, 12.5 * M_PI / 180.0, 1e-12);
  // The preset's own beam prior, and a sensor's set in the file over the map's.
  EXPECT_EQ(scan->spec.beam_prior_length_m, 5.0);
  EXPECT_EQ(kinect->spec.beam_prior_length_m, 0.0);
  fusion::v1::SensorConfig own = config.sensors(0);
  own.set_beam_prior_length_m(2.5);
  auto with_prior = SensorSetupFromConfig(own);
  ASSERT_TRUE(with_prior.ok()) << with_prior.status().message();
  EXPECT_EQ(with_prior->spec.beam_prior_length_m, 2.5);
}

TEST(ConfigProtoTest, SensorFlagAddsAPresetSensor) {
  fusion::v1::SensorConfig sensor;
  fusion::Status status;
  ASSERT_TRUE((status = ParseSensorFlag("front=sr3000", &sensor)).ok());
  EXPECT_EQ(sensor.id(), "front");
  EXPECT_EQ(sensor.preset(), "sr3000");
  EXPECT_FALSE((status = ParseSensorFlag("front", &sensor)).ok());
  EXPECT_FALSE((status = ParseSensorFlag("=sr3000", &sensor)).ok());
}

}  // namespace
}  // namespace fusion::service
