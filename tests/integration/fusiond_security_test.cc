// gRPC security end to end (issue 15): a fusiond with TLS and bearer tokens refuses plaintext
// clients, calls without a token or with an unknown one (UNAUTHENTICATED) and admin calls
// with a read token (PERMISSION_DENIED); with a client CA it refuses clients without a
// certificate. Certificates and tokens come from scripts/make_certs.sh, made per test.
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "../support/fusiond_fixture.h"
#include "grpc/health/v1/health.grpc.pb.h"

namespace {

using namespace fusion::testing;  // NOLINT: the fixture and its helpers
using namespace std::chrono_literals;
namespace v1 = fusion::v1;
namespace fs = std::filesystem;

// The project's source folder: FUSION_SHARED_DATA_DIR is "<source>/../shared/data".
std::string SourceDir() {
  const std::string data = FUSION_SHARED_DATA_DIR;
  return data.substr(0, data.size() - std::string("/../shared/data").size());
}

std::string ReadLine(const std::string& path) {
  std::ifstream in(path);
  std::string line;
  std::getline(in, line);
  return line;
}

class FusiondSecurityTest : public FusiondServiceTest {
 protected:
  void SetUp() override {
    FusiondServiceTest::SetUp();
    certs_ = dir_ + "/certs";
    const std::string command = SourceDir() + "/scripts/make_certs.sh " + certs_ + " > /dev/null";
    ASSERT_EQ(std::system(command.c_str()), 0) << command;
  }

  // Starts fusiond with `security` (text format) added to the fixture's configuration; the
  // port in *port.
  std::unique_ptr<Subprocess> StartSecure(const std::string& security, std::string* port) {
    std::ofstream(config_, std::ios::app) << "security { " << security << " }\n";
    auto process =
        std::make_unique<Subprocess>(std::vector<std::string>{kFusiond, "--config", config_});
    const auto found = process->WaitForOutput(R"(listening on 127\.0\.0\.1:(\d+))", 20s);
    EXPECT_TRUE(found) << "no port line in: " << process->output();
    if (!found) return nullptr;
    *port = *found;
    return process;
  }

  std::string Tls() const {
    return "tls_cert_file: \"" + certs_ + "/server.pem\" tls_key_file: \"" + certs_ +
           "/server.key\" ";
  }

  std::shared_ptr<grpc::ChannelCredentials> TlsCredentials(bool client_certificate,
                                                           const std::string& token) const {
    grpc::SslCredentialsOptions options;
    options.pem_root_certs = ReadFile(certs_ + "/ca.pem");
    if (client_certificate) {
      options.pem_private_key = ReadFile(certs_ + "/client.key");
      options.pem_cert_chain = ReadFile(certs_ + "/client.pem");
    }
    auto credentials = grpc::SslCredentials(options);
    if (token.empty()) return credentials;
    return grpc::CompositeChannelCredentials(credentials, grpc::AccessTokenCredentials(token));
  }

  static std::string ReadFile(const std::string& path) {
    std::ifstream in(path);
    std::stringstream buffer;
    buffer << in.rdbuf();
    return buffer.str();
  }

  static grpc::StatusCode QueryCode(const std::shared_ptr<grpc::Channel>& channel) {
    grpc::ClientContext context;
    context.set_deadline(In(5s));
    v1::QueryPointsRequest request;
    *request.add_points() = P(kInFront);
    v1::QueryPointsResponse reply;
    return v1::FusionMap::NewStub(channel)->QueryPoints(&context, request, &reply).error_code();
  }

  static grpc::Status Reset(const std::shared_ptr<grpc::Channel>& channel) {
    grpc::ClientContext context;
    context.set_deadline(In(5s));
    v1::ResetMapResponse reply;
    return v1::FusionMap::NewStub(channel)->ResetMap(&context, v1::ResetMapRequest(), &reply);
  }

  std::string certs_;
};

TEST_F(FusiondSecurityTest, TokensDecideWhoMayCallWhat) {
  std::string port;
  auto fusiond = StartSecure(Tls() + "tokens_file: \"" + certs_ + "/tokens\"", &port);
  ASSERT_TRUE(fusiond);
  const std::string address = "127.0.0.1:" + port;
  const auto admin = ReadLine(certs_ + "/admin.token");
  const auto read = ReadLine(certs_ + "/read.token");

  // Plaintext against TLS: the handshake fails, nothing is answered.
  EXPECT_EQ(QueryCode(grpc::CreateChannel(address, grpc::InsecureChannelCredentials())),
            grpc::StatusCode::UNAVAILABLE);
  // TLS without a token, with an unknown one.
  EXPECT_EQ(QueryCode(grpc::CreateChannel(address, TlsCredentials(false, ""))),
            grpc::StatusCode::UNAUTHENTICATED);
  EXPECT_EQ(QueryCode(grpc::CreateChannel(address, TlsCredentials(false, read + "x"))),
            grpc::StatusCode::UNAUTHENTICATED);
  // A read token queries, and may not reset.
  const auto reader = grpc::CreateChannel(address, TlsCredentials(false, read));
  EXPECT_EQ(QueryCode(reader), grpc::StatusCode::OK);
  const auto denied = Reset(reader);
  EXPECT_EQ(denied.error_code(), grpc::StatusCode::PERMISSION_DENIED);
  EXPECT_NE(denied.error_message().find("admin"), std::string::npos) << denied.error_message();
  // Health needs a token too (a read one).
  {
    grpc::ClientContext context;
    context.set_deadline(In(5s));
    grpc::health::v1::HealthCheckResponse reply;
    EXPECT_TRUE(grpc::health::v1::Health::NewStub(reader)
                    ->Check(&context, grpc::health::v1::HealthCheckRequest(), &reply)
                    .ok());
    EXPECT_EQ(reply.status(), grpc::health::v1::HealthCheckResponse::SERVING);
  }
  // An admin token resets.
  EXPECT_TRUE(Reset(grpc::CreateChannel(address, TlsCredentials(false, admin))).ok());

  // fusionctl with the same files: stats with the read token, reset refused with it and done
  // with the admin token, nothing without a token.
  const auto fusionctl = [&](const std::vector<std::string>& args, std::string* out) {
    std::vector<std::string> argv{std::string(FUSION_BINARY_DIR) + "/clients/fusionctl",
                                  "--server", address, "--tls-ca", certs_ + "/ca.pem"};
    argv.insert(argv.end(), args.begin(), args.end());
    Subprocess process({"/bin/sh", "-c", [&] {
                          std::string command = "exec";
                          for (const auto& a : argv) command += " '" + a + "'";
                          return command + " 2>&1";
                        }()});
    process.WaitForOutput("(?!)", 20s);
    const int code = process.Wait(5s);
    *out = process.output();
    return code;
  };
  std::string out;
  EXPECT_EQ(fusionctl({"--token-file", certs_ + "/read.token", "stats"}, &out), 0) << out;
  EXPECT_NE(out.find("clouds_in_map"), std::string::npos) << out;
  EXPECT_NE(fusionctl({"--token-file", certs_ + "/read.token", "reset"}, &out), 0) << out;
  EXPECT_NE(out.find("PERMISSION_DENIED"), std::string::npos) << out;
  EXPECT_EQ(fusionctl({"--token-file", certs_ + "/admin.token", "reset"}, &out), 0) << out;
  EXPECT_NE(fusionctl({"stats"}, &out), 0) << out;
  EXPECT_NE(out.find("UNAUTHENTICATED"), std::string::npos) << out;
  EXPECT_EQ(fusiond->Stop(SIGTERM, 15s), 0);
}

TEST_F(FusiondSecurityTest, MutualTlsRefusesClientsWithoutACertificate) {
  std::string port;
  auto fusiond = StartSecure(Tls() + "tls_client_ca_file: \"" + certs_ + "/ca.pem\"", &port);
  ASSERT_TRUE(fusiond);
  const std::string address = "127.0.0.1:" + port;
  EXPECT_EQ(QueryCode(grpc::CreateChannel(address, TlsCredentials(false, ""))),
            grpc::StatusCode::UNAVAILABLE);
  EXPECT_EQ(QueryCode(grpc::CreateChannel(address, TlsCredentials(true, ""))),
            grpc::StatusCode::OK);
  EXPECT_EQ(fusiond->Stop(SIGTERM, 15s), 0);
}

TEST_F(FusiondSecurityTest, TokensWithoutTlsAreRefusedNamingTheField) {
  std::ofstream(config_, std::ios::app)
      << "security { tokens_file: \"" << certs_ << "/tokens\" }\n";
  Subprocess fusiond({kFusiond, "--config", config_});
  EXPECT_EQ(fusiond.Wait(10s), 2);
  // The message goes to stderr, which the test's log shows; the exit code is the contract.
}

}  // namespace
