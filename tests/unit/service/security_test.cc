// The token file, the role each method needs, the token check and the static checks of the
// security configuration (security.h); the TLS handshakes are tested end to end
// (tests/integration/fusiond_security_test.cc).
#include "fusion/service/security.h"

#include <gtest/gtest.h>

namespace fusion::service {
namespace {

using grpc::StatusCode;

const std::string kAdmin = "0123456789abcdef-admin";
const std::string kRead = "0123456789abcdef-read";

TEST(SecurityTest, TokensFileLinesCommentsAndErrors) {
  const auto parsed =
      ParseTokens("# tokens\n\nadmin " + kAdmin + "  # ops\n  read " + kRead + "\n");
  ASSERT_TRUE(parsed.ok()) << parsed.status().message();
  const std::vector<Token>& tokens = *parsed;
  ASSERT_EQ(tokens.size(), 2u);
  EXPECT_EQ(tokens[0].role, Role::kAdmin);
  EXPECT_EQ(tokens[0].secret, kAdmin);
  EXPECT_EQ(tokens[1].role, Role::kRead);
  const std::vector<std::string> bad_files = {"writer " + kAdmin, "admin",
                                              "admin " + kAdmin + " extra", "read short",
                                              "# nothing\n"};
  for (const std::string& bad : bad_files) {
    const auto none = ParseTokens(bad);
    EXPECT_FALSE(none.ok()) << bad;
    EXPECT_FALSE(none.status().message().empty());
  }
  const auto second_bad = ParseTokens("read " + kRead + "\nbogus line here\n");
  EXPECT_FALSE(second_bad.ok());
  EXPECT_NE(second_bad.status().message().find("line 2"), std::string::npos)
      << second_bad.status().message();
}

TEST(SecurityTest, OnlyResetAndSaveNeedAdmin) {
  EXPECT_EQ(RequiredRole("/fusion.v1.FusionMap/ResetMap"), Role::kAdmin);
  EXPECT_EQ(RequiredRole("/fusion.v1.FusionMap/SaveMap"), Role::kAdmin);
  EXPECT_EQ(RequiredRole("/fusion.v1.FusionMap/ClearBox"), Role::kAdmin);
  for (const char* method : {"/fusion.v1.FusionMap/QueryPoints", "/fusion.v1.FusionMap/GetSnapshot",
                             "/fusion.v1.FusionMap/StreamUpdates", "/grpc.health.v1.Health/Check",
                             ""}) {
    EXPECT_EQ(RequiredRole(method), Role::kRead) << method;
  }
}

TEST(SecurityTest, BearerTokensAreCheckedAgainstTheRoleOfTheMethod) {
  const TokenAuthProcessor processor({{Role::kAdmin, kAdmin}, {Role::kRead, kRead}});
  const std::string reset = "/fusion.v1.FusionMap/ResetMap";
  const std::string query = "/fusion.v1.FusionMap/QueryPoints";
  EXPECT_TRUE(processor.Check("Bearer " + kAdmin, reset).ok());
  EXPECT_TRUE(processor.Check("Bearer " + kAdmin, query).ok());
  EXPECT_TRUE(processor.Check("Bearer " + kRead, query).ok());
  EXPECT_EQ(processor.Check("Bearer " + kRead, reset).error_code(), StatusCode::PERMISSION_DENIED);
  EXPECT_EQ(processor.Check("", query).error_code(), StatusCode::UNAUTHENTICATED);
  EXPECT_EQ(processor.Check(kRead, query).error_code(), StatusCode::UNAUTHENTICATED);  // no scheme
  EXPECT_EQ(processor.Check("Basic " + kRead, query).error_code(), StatusCode::UNAUTHENTICATED);
  EXPECT_EQ(processor.Check("Bearer " + kRead.substr(1), query).error_code(),
            StatusCode::UNAUTHENTICATED);  // a prefix is not the token
  EXPECT_EQ(processor.Check("Bearer " + kRead + "0", query).error_code(),
            StatusCode::UNAUTHENTICATED);
  EXPECT_EQ(processor.Check("Bearer ", query).error_code(), StatusCode::UNAUTHENTICATED);
}

fusion::v1::SecurityConfig Security(const std::string& cert, const std::string& key,
                                    const std::string& client_ca, const std::string& tokens) {
  fusion::v1::SecurityConfig security;
  security.set_tls_cert_file(cert);
  security.set_tls_key_file(key);
  security.set_tls_client_ca_file(client_ca);
  security.set_tokens_file(tokens);
  return security;
}

TEST(SecurityTest, StaticChecksNameTheField) {
  EXPECT_TRUE(ValidateSecurity(Security("", "", "", "")).ok());
  EXPECT_TRUE(ValidateSecurity(Security("c", "k", "ca", "t")).ok());
  const std::pair<fusion::v1::SecurityConfig, std::string> bad[] = {
      {Security("c", "", "", ""), "security.tls_key_file"},
      {Security("", "k", "", ""), "security.tls_cert_file"},
      {Security("", "", "ca", ""), "security.tls_client_ca_file"},
      {Security("", "", "", "t"), "security.tokens_file"},
  };
  for (const auto& [security, field] : bad) {
    const fusion::Status checked = ValidateSecurity(security);
    EXPECT_FALSE(checked.ok()) << field;
    EXPECT_EQ(checked.message().rfind(field, 0), 0u) << checked.message();
  }
}

TEST(SecurityTest, ReflectionFollowsTokensUnlessConfigured) {
  auto security = Security("", "", "", "");
  EXPECT_TRUE(ReflectionEnabled(security));
  security = Security("c", "k", "", "t");
  EXPECT_FALSE(ReflectionEnabled(security));
  security.set_reflection(true);
  EXPECT_TRUE(ReflectionEnabled(security));
}

TEST(SecurityTest, UnreadableFilesAreErrors) {
  const auto missing = ServerCredentialsFor(Security("/nonexistent.pem", "/nonexistent.key", "", ""));
  EXPECT_FALSE(missing.ok());
  EXPECT_NE(missing.status().message().find("/nonexistent"), std::string::npos)
      << missing.status().message();
  const auto plaintext = ServerCredentialsFor(Security("", "", "", ""));
  ASSERT_TRUE(plaintext.ok());
  EXPECT_NE(*plaintext, nullptr);
}

}  // namespace
}  // namespace fusion::service
