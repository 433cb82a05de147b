// Who may call fusiond's gRPC API (docs/security.md): TLS and mutual TLS with gRPC's own
// credentials, and bearer tokens with two roles, checked for every call (FusionMap, health,
// reflection) before it reaches a handler.
#pragma once

#include <grpcpp/security/auth_metadata_processor.h>
#include <grpcpp/security/server_credentials.h>

#include <memory>
#include <string>
#include <vector>

#include "fusion/core/status.h"
#include "fusion/v1/config.pb.h"

namespace fusion::service {

enum class Role { kRead, kAdmin };

struct Token {
  Role role = Role::kRead;
  std::string secret;
};

// Parses a tokens file's text: lines "<role> <token>", role read or admin, '#' comments and
// blank lines skipped. The error names the line of a malformed one, or says there is no token.
[[nodiscard]] fusion::StatusOr<std::vector<Token>> ParseTokens(const std::string& text);

// The role a call needs: admin for the calls that change or write the map, read otherwise.
// `method` is the gRPC path, "/fusion.v1.FusionMap/ResetMap".
[[nodiscard]] Role RequiredRole(const std::string& method);

// Checks the "authorization: Bearer <token>" metadata of every call against the tokens (each
// compared in constant time) and the role the method needs: UNAUTHENTICATED without a known
// token, PERMISSION_DENIED for a read token on an admin call.
class TokenAuthProcessor final : public grpc::AuthMetadataProcessor {
 public:
  explicit TokenAuthProcessor(std::vector<Token> tokens) : tokens_(std::move(tokens)) {}
  [[nodiscard]] bool IsBlocking() const override { return false; }
  grpc::Status Process(const InputMetadata& auth_metadata, grpc::AuthContext* context,
                       OutputMetadata* consumed, OutputMetadata* response) override;
  // The same decision without gRPC's types, for tests: the authorization value and method.
  [[nodiscard]] grpc::Status Check(const std::string& authorization,
                                   const std::string& method) const;

 private:
  std::vector<Token> tokens_;
};

// The static checks of `security` (files named in pairs, TLS under tokens): the error names
// the field (fusiond exits 2).
[[nodiscard]] fusion::Status ValidateSecurity(const fusion::v1::SecurityConfig& security);

// Server credentials for the configuration: insecure without TLS; TLS (mutual with a client
// CA) with the files read; the token processor attached when tokens are configured. An error
// when a file cannot be read or parsed.
[[nodiscard]] fusion::StatusOr<std::shared_ptr<grpc::ServerCredentials>> ServerCredentialsFor(
    const fusion::v1::SecurityConfig& security);

// Whether gRPC server reflection is on: as configured, else on without tokens.
[[nodiscard]] bool ReflectionEnabled(const fusion::v1::SecurityConfig& security);

}  // namespace fusion::service
