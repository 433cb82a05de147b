// Protobuf round trips of the configuration and the errors a bad file gets.
#include <cstdio>
#include <fstream>
#include <string>

#include <google/protobuf/text_format.h>
#include <google/protobuf/util/json_util.h>
#include <google/protobuf/util/message_differencer.h>
#include <gtest/gtest.h>

#include "fusion/service/config.h"

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
  std::string error;
  ASSERT_TRUE(LoadConfigFile(path, &config, &error)) << error;
  EXPECT_EQ(config.dds_domain(), 42u);
  EXPECT_EQ(config.log_level(), "debug");
  EXPECT_EQ(config.listen_address(), "127.0.0.1:0");  // default kept
}

TEST(ConfigProtoTest, BadFilesAreRefusedWithTheFieldNamed) {
  std::string error;
  auto config = DefaultConfig();
  EXPECT_FALSE(LoadConfigFile(WriteTemp("bad1.pbtxt", "dds_domian: 3\n"), &config, &error));
  EXPECT_NE(error.find("dds_domian"), std::string::npos) << error;
  EXPECT_NE(error.find("line 1"), std::string::npos) << error;

  config = DefaultConfig();
  EXPECT_FALSE(LoadConfigFile(WriteTemp("bad2.pbtxt", "dds_domain: 999\n"), &config, &error));
  EXPECT_NE(error.find("dds_domain"), std::string::npos) << error;

  config = DefaultConfig();
  EXPECT_FALSE(LoadConfigFile(WriteTemp("bad3.json", "{\"logLevel\": \"loud\"}"), &config, &error));
  EXPECT_NE(error.find("log_level"), std::string::npos) << error;

  EXPECT_FALSE(LoadConfigFile("/nonexistent/fusiond.pbtxt", &config, &error));
  EXPECT_NE(error.find("cannot open"), std::string::npos) << error;
}

}  // namespace
}  // namespace fusion::service
