// fusiond's log (logging.h): JSON lines that parse whatever the message holds, and foreign
// console output (std::cout, std::cerr, fprintf(stderr)) routed through the logger "octomap"
// with a level read from the line.
#include "fusion/service/logging.h"

#include <fcntl.h>
#include <gtest/gtest.h>
#include <spdlog/spdlog.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <thread>
#include <vector>

#include "../../support/json_line.h"

namespace fusion::service {
namespace {

using Struct = std::map<std::string, std::string>;

Struct Parse(const std::string& line) {
  const auto object = fusion::testing::ParseFlatJsonObject(line);
  EXPECT_TRUE(object) << "not one flat JSON object: " << line;
  return object.value_or(Struct());
}

std::string Field(const Struct& object, const std::string& key) {
  const auto it = object.find(key);
  return it == object.end() ? "" : it->second;
}

TEST(LoggingTest, JsonLinesEscapeWhatTheMessageHolds) {
  const std::string message = "id \"a\\b\"\nsecond line\t\x01 end \xc3\xa9";
  const Struct object = Parse(JsonLogLine("2026-12-02T00:00:00.000000Z", "warning", "fusiond",
                                          message, 42, 7));
  EXPECT_EQ(Field(object, "message"), message);
  EXPECT_EQ(Field(object, "level"), "warning");
  EXPECT_EQ(Field(object, "logger"), "fusiond");
  EXPECT_EQ(Field(object, "time"), "2026-12-02T00:00:00.000000Z");
  EXPECT_EQ(Field(object, "pid"), "42");
  EXPECT_EQ(Field(object, "thread"), "7");
  EXPECT_FALSE(fusion::testing::ParseFlatJsonObject("{\"a\":\"raw\nnewline\"}"));  // the reader
  EXPECT_FALSE(fusion::testing::ParseFlatJsonObject("{\"a\":1} trailing"));           // is strict
}

TEST(LoggingTest, ForeignConsoleLinesBecomeLogLines) {
  // The log goes to "stderr": here a file put on fd 2 first.
  const std::string path = ::testing::TempDir() + "logging_test_" + std::to_string(::getpid());
  const int file = ::open(path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0600);
  ASSERT_GE(file, 0);
  const int saved = ::dup(STDERR_FILENO);
  ASSERT_EQ(::dup2(file, STDERR_FILENO), STDERR_FILENO);
  ::close(file);

  SetUpLogging("json", "debug");
  spdlog::info("ours");
  std::cerr << "WARNING: from std::cerr" << std::endl;
  std::cout << "Reading octree type OcTree\n";
  std::cout << " done." << std::endl;  // OctoMap's lone " done."
  std::fprintf(stderr, "ERROR: from fprintf\n");
  std::fflush(stderr);
  std::this_thread::sleep_for(std::chrono::milliseconds(300));  // the fd-2 reader's turn
  spdlog::default_logger()->flush();
  spdlog::get("octomap")->flush();

  std::vector<Struct> lines;
  std::vector<std::string> raw;
  std::ifstream in(path);
  for (std::string line; std::getline(in, line);) {
    raw.push_back(line);
    if (!line.empty() && line.front() == '{') lines.push_back(Parse(line));
  }
  std::string all;
  for (const auto& line : raw) all += line + "\n";
  const auto find = [&](const std::string& message) -> const Struct* {
    for (const auto& object : lines) {
      if (Field(object, "message") == message) return &object;
    }
    return nullptr;
  };
  ASSERT_NE(find("ours"), nullptr) << all;
  const Struct* warning = find("WARNING: from std::cerr");
  ASSERT_NE(warning, nullptr) << all;
  EXPECT_EQ(Field(*warning, "logger"), "octomap");
  EXPECT_EQ(Field(*warning, "level"), "warning");
  const Struct* chatter = find("Reading octree type OcTree");
  ASSERT_NE(chatter, nullptr) << all;
  EXPECT_EQ(Field(*chatter, "level"), "debug");
  ASSERT_NE(find("done."), nullptr) << all;
  if (CapturesFd2()) {
    const Struct* error = find("ERROR: from fprintf");
    ASSERT_NE(error, nullptr) << all;
    EXPECT_EQ(Field(*error, "level"), "error");
    EXPECT_EQ(lines.size(), raw.size()) << "a line that is not JSON:\n" << all;
  }
  ::dup2(saved, STDERR_FILENO);
  ::close(saved);
  std::remove(path.c_str());
}

}  // namespace
}  // namespace fusion::service
