// fusiond as a real process: starts on 127.0.0.1:0, reports its port, answers the standard
// gRPC health check, refuses bad configuration and stops cleanly on SIGTERM.
#include <csignal>
#include <string>

#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include "../support/subprocess.h"
#include "grpc/health/v1/health.grpc.pb.h"

namespace {

using fusion::testing::Subprocess;
using namespace std::chrono_literals;

const std::string kFusiond = std::string(FUSION_BINARY_DIR) + "/service/fusiond";

grpc::health::v1::HealthCheckResponse::ServingStatus Check(const std::string& address,
                                                           const std::string& service) {
  auto stub = grpc::health::v1::Health::NewStub(
      grpc::CreateChannel(address, grpc::InsecureChannelCredentials()));
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + 5s);
  grpc::health::v1::HealthCheckRequest request;
  request.set_service(service);
  grpc::health::v1::HealthCheckResponse reply;
  const auto status = stub->Check(&context, request, &reply);
  EXPECT_TRUE(status.ok()) << status.error_message();
  return reply.status();
}

TEST(FusiondProcessTest, AnswersHealthCheckAndStopsCleanly) {
  Subprocess fusiond({kFusiond, "--listen", "127.0.0.1:0", "--dds-domain",
                      std::to_string(fusion::testing::PrivateDomainId()), "--log-level", "warn"});
  ASSERT_TRUE(fusiond.started());
  const auto port = fusiond.WaitForOutput(R"(listening on 127\.0\.0\.1:(\d+))", 20s);
  ASSERT_TRUE(port) << "no port line in: " << fusiond.output();
  ASSERT_NE(*port, "0");
  const std::string address = "127.0.0.1:" + *port;
  EXPECT_EQ(Check(address, ""), grpc::health::v1::HealthCheckResponse::SERVING);
  EXPECT_EQ(Check(address, "fusion.v1.FusionMap"), grpc::health::v1::HealthCheckResponse::SERVING);
  EXPECT_EQ(fusiond.Stop(SIGTERM, 10s), 0);
}

TEST(FusiondProcessTest, RefusesBadOptionsWithAMessage) {
  Subprocess bad({kFusiond, "--log-level", "loud"});
  EXPECT_EQ(bad.Wait(10s), 2);
  Subprocess help({kFusiond, "--help"});
  EXPECT_TRUE(help.WaitForOutput("Usage: fusiond", 10s));
  EXPECT_EQ(help.Wait(10s), 0);
}

}  // namespace
