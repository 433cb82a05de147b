// fusionctl's command line: strict options and arity (exit 2), per-command --help, --json,
// per-command default deadlines, and the TLS / bearer-token options with their environment
// fallbacks.
#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>

#include "command_line.h"
#include "run_fusionctl.h"

namespace fusionctl {
namespace {

using testing::RunFusionctl;
constexpr int kExitUsage = fusion::clients::kExitUsage;

struct Parsed {
  std::optional<int> done;
  Context ctx;
  const CommandSpec* command = nullptr;
  Args args;
};

Parsed Parse(std::vector<std::string> words) {
  words.insert(words.begin(), "fusionctl");
  std::vector<char*> argv;
  for (auto& w : words) argv.push_back(w.data());
  Parsed p;
  ::testing::internal::CaptureStdout();
  ::testing::internal::CaptureStderr();
  p.done =
      ParseCommandLine(static_cast<int>(argv.size()), argv.data(), &p.ctx, &p.command, &p.args);
  ::testing::internal::GetCapturedStdout();
  ::testing::internal::GetCapturedStderr();
  return p;
}

// Nothing listens there: a command that got past its checks would fail with 1, not 2.
const std::string kNowhere = "127.0.0.1:1";

TEST(FusionctlCommandLineTest, UnknownOptionsAreUsageErrors) {
  for (const std::vector<std::string>& words :
       {std::vector<std::string>{"reset", "--yes-really"},
        {"stats", "--limit", "5"},
        {"--bogus", "stats"},
        {"box", "0", "0", "0", "1", "1", "1", "--stat", "free"},
        {"watch", "-x"},
        {"health", "--"}}) {
    std::vector<std::string> args = {"--server", kNowhere};
    args.insert(args.end(), words.begin(), words.end());
    const auto r = RunFusionctl(args);
    EXPECT_EQ(r.exit_code, kExitUsage) << ::testing::PrintToString(words) << r.err;
    EXPECT_NE(r.err.find("unknown"), std::string::npos) << r.err;
  }
}

TEST(FusionctlCommandLineTest, ExtraOrMissingArgumentsAreUsageErrors) {
  for (const std::vector<std::string>& words :
       {std::vector<std::string>{"stats", "extra"},
        {"reset", "now"},
        {"box", "0", "0", "0", "1", "1", "1", "7"},
        {"box", "0", "0", "0"},
        {"beam", "sr", "1"},
        {"snapshot", "a.ot", "b.ot"},
        {"planes", "1"},
        {"planes", "--region", "0", "0", "0"},
        {"watch", "5"},
        {"points"},
        {"beam", "sr", "x", "1"},
        {"box", "0", "0", "0", "1", "1", "1", "--limit", "ten"},
        {"watch", "--count", "-1"},
        {"planes", "--max", "65"},
        {"stats", "--timeout", "0"},
        {"render", "map.png", "--color"},
        {"render", "map.png", "--size", "64x48px"}}) {
    std::vector<std::string> args = {"--server", kNowhere};
    args.insert(args.end(), words.begin(), words.end());
    const auto r = RunFusionctl(args);
    EXPECT_EQ(r.exit_code, kExitUsage) << ::testing::PrintToString(words) << r.err;
  }
}

TEST(FusionctlCommandLineTest, NegativeNumbersAreArgumentsNotOptions) {
  const auto p = Parse({"box", "-1", "-2.5", "-3", "1", "2", "3e0"});
  EXPECT_FALSE(p.done);
  EXPECT_EQ(p.args.positional.size(), 6u);
}

TEST(FusionctlCommandLineTest, EveryCommandHasItsOwnHelp) {
  for (const auto& spec : Commands()) {
    for (const std::vector<std::string>& words :
         {std::vector<std::string>{spec.name, "--help"}, {"-h", spec.name}}) {
      const auto r = RunFusionctl(words);
      EXPECT_EQ(r.exit_code, 0) << spec.name;
      EXPECT_EQ(r.out.rfind(std::string("Usage: fusionctl ") + spec.name, 0), 0u)
          << spec.name << ": " << r.out;
      EXPECT_EQ(r.out.find("Commands:"), std::string::npos) << "global text for " << spec.name;
    }
  }
  const auto global = RunFusionctl({"--help"});
  EXPECT_EQ(global.exit_code, 0);
  EXPECT_NE(global.out.find("Commands:"), std::string::npos);
}

TEST(FusionctlCommandLineTest, JsonIsAGlobalOptionAnywhere) {
  EXPECT_FALSE(Parse({"stats"}).ctx.json);
  EXPECT_TRUE(Parse({"--json", "stats"}).ctx.json);
  EXPECT_TRUE(Parse({"stats", "--json"}).ctx.json);
}

TEST(FusionctlCommandLineTest, DefaultDeadlineSuitsTheCommand) {
  EXPECT_DOUBLE_EQ(Parse({"stats"}).ctx.timeout_s, 10.0);
  EXPECT_DOUBLE_EQ(Parse({"points", "1,2,3"}).ctx.timeout_s, 10.0);
  // Heavy calls on fusiond's low-priority pool.
  EXPECT_GE(Parse({"planes"}).ctx.timeout_s, 60.0);
  EXPECT_GE(Parse({"snapshot", "m.bt"}).ctx.timeout_s, 60.0);
  EXPECT_GE(Parse({"render", "m.png"}).ctx.timeout_s, 60.0);
  EXPECT_DOUBLE_EQ(Parse({"watch"}).ctx.timeout_s, 0.0);  // a stream: no deadline
  // --timeout wins, for heavy calls too.
  EXPECT_DOUBLE_EQ(Parse({"planes", "--timeout", "2.5"}).ctx.timeout_s, 2.5);
  EXPECT_DOUBLE_EQ(Parse({"--timeout", "3", "watch"}).ctx.timeout_s, 3.0);
}

TEST(FusionctlStatusNameTest, EveryCodeHasItsName) {
  EXPECT_STREQ(StatusCodeName(grpc::StatusCode::OK), "OK");
  EXPECT_STREQ(StatusCodeName(grpc::StatusCode::INVALID_ARGUMENT), "INVALID_ARGUMENT");
  EXPECT_STREQ(StatusCodeName(grpc::StatusCode::DEADLINE_EXCEEDED), "DEADLINE_EXCEEDED");
  EXPECT_STREQ(StatusCodeName(grpc::StatusCode::RESOURCE_EXHAUSTED), "RESOURCE_EXHAUSTED");
  EXPECT_STREQ(StatusCodeName(grpc::StatusCode::FAILED_PRECONDITION), "FAILED_PRECONDITION");
  EXPECT_STREQ(StatusCodeName(grpc::StatusCode::UNAVAILABLE), "UNAVAILABLE");
  EXPECT_STREQ(StatusCodeName(grpc::StatusCode::DATA_LOSS), "DATA_LOSS");
  EXPECT_STREQ(StatusCodeName(grpc::StatusCode::UNAUTHENTICATED), "UNAUTHENTICATED");
  EXPECT_STREQ(StatusCodeName(99), "UNKNOWN_STATUS");  // a code from a newer peer
  EXPECT_STREQ(StatusCodeName(-1), "UNKNOWN_STATUS");
}

class ConnectionOptionsTest : public ::testing::Test {
 protected:
  void SetUp() override { Clear(); }
  void TearDown() override { Clear(); }
  static void Clear() {
    for (const char* name : {"FUSION_TLS_CA", "FUSION_TLS_CERT", "FUSION_TLS_KEY",
                             "FUSION_TOKEN_FILE", "FUSIOND_ADDRESS"}) {
      unsetenv(name);
    }
  }
};

void ExpectConnection(const ConnectionOptions& got, const ConnectionOptions& want) {
  EXPECT_EQ(got.server, want.server);
  EXPECT_EQ(got.tls_ca_path, want.tls_ca_path);
  EXPECT_EQ(got.tls_cert_path, want.tls_cert_path);
  EXPECT_EQ(got.tls_key_path, want.tls_key_path);
  EXPECT_EQ(got.token_file_path, want.token_file_path);
}

TEST_F(ConnectionOptionsTest, FlagsThenEnvironment) {
  auto p = Parse({"--tls-ca", "ca.pem", "--tls-cert", "c.pem", "--tls-key", "k.pem", "--token-file",
                  "t", "--server", "h:1", "stats"});
  ASSERT_FALSE(p.done);
  ExpectConnection(p.ctx.connection, {"h:1", "ca.pem", "c.pem", "k.pem", "t"});

  setenv("FUSION_TLS_CA", "env-ca.pem", 1);
  setenv("FUSION_TLS_CERT", "env-c.pem", 1);
  setenv("FUSION_TLS_KEY", "env-k.pem", 1);
  setenv("FUSION_TOKEN_FILE", "env-t", 1);
  setenv("FUSIOND_ADDRESS", "env:2", 1);
  p = Parse({"stats"});
  ASSERT_FALSE(p.done);
  ExpectConnection(p.ctx.connection, {"env:2", "env-ca.pem", "env-c.pem", "env-k.pem", "env-t"});
  // A flag wins over its variable.
  EXPECT_EQ(Parse({"--tls-ca", "flag.pem", "stats"}).ctx.connection.tls_ca_path, "flag.pem");
}

TEST_F(ConnectionOptionsTest, ClientKeyPairGoesTogetherAndNeedsTheCa) {
  EXPECT_EQ(Parse({"--tls-ca", "ca", "--tls-cert", "c", "stats"}).done, kExitUsage);
  EXPECT_EQ(Parse({"--tls-ca", "ca", "--tls-key", "k", "stats"}).done, kExitUsage);
  EXPECT_EQ(Parse({"--tls-cert", "c", "--tls-key", "k", "stats"}).done, kExitUsage);
  EXPECT_EQ(Parse({"--tls-ca", "ca", "--tls-cert", "c", "--tls-key", "k", "stats"}).done,
            std::nullopt);
  EXPECT_EQ(Parse({"--tls-ca", "stats"}).done, kExitUsage);  // needs a value ("stats" taken)
}

TEST_F(ConnectionOptionsTest, TokenIsTheFirstLineTrimmed) {
  const std::string path = ::testing::TempDir() + "fusionctl_token_" + std::to_string(getpid());
  std::string token;
  std::ofstream(path) << " \t s3cret-token \r\nsecond line\n";
  ASSERT_TRUE(ReadBearerToken(path, &token).ok());
  EXPECT_EQ(token, "s3cret-token");
  std::ofstream(path) << "   \nnot-the-first-line\n";
  EXPECT_FALSE(ReadBearerToken(path, &token).ok());
  std::filesystem::remove(path);
  EXPECT_FALSE(ReadBearerToken(path, &token).ok());
}

TEST_F(ConnectionOptionsTest, ChannelWithoutTlsIsInsecureAndTlsFilesMustExist) {
  ConnectionOptions options;
  options.server = kNowhere;
  std::shared_ptr<grpc::Channel> channel;
  ASSERT_TRUE(MakeChannel(options, &channel).ok());
  EXPECT_NE(channel, nullptr);
  options.tls_ca_path = ::testing::TempDir() + "no-such-ca.pem";
  const auto s = MakeChannel(options, &channel);
  EXPECT_FALSE(s.ok());
  EXPECT_NE(s.message().find("no-such-ca.pem"), std::string::npos) << s.message();
  // The tool reports it as a failure (1), not as a bad command line.
  const auto r = RunFusionctl({"--tls-ca", options.tls_ca_path, "--server", kNowhere, "stats"});
  EXPECT_EQ(r.exit_code, fusion::clients::kExitFailure) << r.err;
}

}  // namespace
}  // namespace fusionctl
