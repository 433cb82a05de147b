#include "fusion/service/security.h"

#include <fstream>
#include <sstream>

namespace fusion::service {
namespace {

using grpc::Status;
using grpc::StatusCode;

// Equal in time that depends on the lengths only, not on where the bytes differ.
bool ConstantTimeEqual(const std::string& a, const std::string& b) {
  unsigned char diff = a.size() == b.size() ? 0 : 1;
  const std::size_t n = std::max(a.size(), b.size());
  for (std::size_t i = 0; i < n; ++i) {
    const unsigned char x = i < a.size() ? static_cast<unsigned char>(a[i]) : 0;
    const unsigned char y = i < b.size() ? static_cast<unsigned char>(b[i]) : 0;
    diff |= x ^ y;
  }
  return diff == 0;
}

fusion::StatusOr<std::string> ReadFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream buffer;
  if (in) buffer << in.rdbuf();
  if (!in || in.bad()) return fusion::Status::Error("cannot read '" + path + "'");
  return buffer.str();
}

}  // namespace

fusion::StatusOr<std::vector<Token>> ParseTokens(const std::string& text) {
  std::vector<Token> tokens;
  std::istringstream lines(text);
  std::string line;
  for (int number = 1; std::getline(lines, line); ++number) {
    const auto hash = line.find('#');
    if (hash != std::string::npos) line.erase(hash);
    std::istringstream fields(line);
    std::string role, secret, extra;
    if (!(fields >> role)) continue;  // blank
    const std::string at = "line " + std::to_string(number) + ": ";
    if (!(fields >> secret) || (fields >> extra) || (role != "read" && role != "admin")) {
      return fusion::Status::Error(at + "expected '<read|admin> <token>'");
    }
    if (secret.size() < 16) return fusion::Status::Error(at + "a token needs at least 16 characters");
    tokens.push_back({role == "admin" ? Role::kAdmin : Role::kRead, secret});
  }
  if (tokens.empty()) return fusion::Status::Error("no token in the file");
  return tokens;
}

Role RequiredRole(const std::string& method) {
  static const char* const kAdminMethods[] = {"/fusion.v1.FusionMap/ResetMap",
                                              "/fusion.v1.FusionMap/ClearBox",
                                              "/fusion.v1.FusionMap/SaveMap"};
  for (const char* admin : kAdminMethods) {
    if (method == admin) return Role::kAdmin;
  }
  return Role::kRead;
}

Status TokenAuthProcessor::Check(const std::string& authorization,
                                 const std::string& method) const {
  static const std::string kBearer = "Bearer ";
  if (authorization.compare(0, kBearer.size(), kBearer) != 0) {
    return Status(StatusCode::UNAUTHENTICATED,
                  "this fusiond needs 'authorization: Bearer <token>' (--token-file)");
  }
  const std::string presented = authorization.substr(kBearer.size());
  const Token* match = nullptr;
  for (const Token& token : tokens_) {  // every token compared: no early exit
    if (ConstantTimeEqual(presented, token.secret)) match = &token;
  }
  if (match == nullptr) return Status(StatusCode::UNAUTHENTICATED, "unknown token");
  if (RequiredRole(method) == Role::kAdmin && match->role != Role::kAdmin) {
    return Status(StatusCode::PERMISSION_DENIED, method + " needs an admin token");
  }
  return Status::OK;
}

Status TokenAuthProcessor::Process(const InputMetadata& auth_metadata, grpc::AuthContext*,
                                   OutputMetadata* consumed, OutputMetadata*) {
  std::string authorization, method;
  for (const auto& [key, value] : auth_metadata) {
    if (key == "authorization") authorization.assign(value.data(), value.size());
    if (key == ":path") method.assign(value.data(), value.size());
  }
  Status status = Check(authorization, method);
  if (status.ok()) consumed->emplace("authorization", authorization);  // handlers never see it
  return status;
}

fusion::Status ValidateSecurity(const fusion::v1::SecurityConfig& security) {
  const auto fail = [](const std::string& field, const std::string& why) {
    return fusion::Status::Error("security." + field + ": " + why);
  };
  if (security.tls_cert_file().empty() != security.tls_key_file().empty()) {
    return fail(security.tls_cert_file().empty() ? "tls_cert_file" : "tls_key_file",
                "tls_cert_file and tls_key_file go together");
  }
  const bool tls = !security.tls_cert_file().empty();
  if (!security.tls_client_ca_file().empty() && !tls) {
    return fail("tls_client_ca_file", "mutual TLS needs tls_cert_file and tls_key_file");
  }
  if (!security.tokens_file().empty() && !tls) {
    return fail("tokens_file",
                "tokens need TLS (tls_cert_file, tls_key_file): gRPC sends them only over a "
                "secure channel");
  }
  return fusion::Status::Ok();
}

fusion::StatusOr<std::shared_ptr<grpc::ServerCredentials>> ServerCredentialsFor(
    const fusion::v1::SecurityConfig& security) {
  if (security.tls_cert_file().empty()) return grpc::InsecureServerCredentials();
  grpc::SslServerCredentialsOptions options(
      security.tls_client_ca_file().empty()
          ? GRPC_SSL_DONT_REQUEST_CLIENT_CERTIFICATE
          : GRPC_SSL_REQUEST_AND_REQUIRE_CLIENT_CERTIFICATE_AND_VERIFY);
  auto key = ReadFile(security.tls_key_file());
  if (!key.ok()) return key.status();
  auto cert = ReadFile(security.tls_cert_file());
  if (!cert.ok()) return cert.status();
  options.pem_key_cert_pairs.push_back({std::move(*key), std::move(*cert)});
  if (!security.tls_client_ca_file().empty()) {
    auto ca = ReadFile(security.tls_client_ca_file());
    if (!ca.ok()) return ca.status();
    options.pem_root_certs = std::move(*ca);
  }
  auto credentials = grpc::SslServerCredentials(options);
  if (!security.tokens_file().empty()) {
    auto text = ReadFile(security.tokens_file());
    if (!text.ok()) return text.status();
    auto tokens = ParseTokens(*text);
    if (!tokens.ok()) return tokens.status().WithContext(security.tokens_file());
    credentials->SetAuthMetadataProcessor(
        std::make_shared<TokenAuthProcessor>(std::move(*tokens)));
  }
  return credentials;
}

bool ReflectionEnabled(const fusion::v1::SecurityConfig& security) {
  return security.has_reflection() ? security.reflection() : security.tokens_file().empty();
}

}  // namespace fusion::service
