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

bool ReadFile(const std::string& path, std::string* text, std::string* error) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream buffer;
  if (in) buffer << in.rdbuf();
  if (!in || in.bad()) {
    *error = "cannot read '" + path + "'";
    return false;
  }
  *text = buffer.str();
  return true;
}

}  // namespace

bool ParseTokens(const std::string& text, std::vector<Token>* tokens, std::string* error) {
  std::istringstream lines(text);
  std::string line;
  for (int number = 1; std::getline(lines, line); ++number) {
    const auto hash = line.find('#');
    if (hash != std::string::npos) line.erase(hash);
    std::istringstream fields(line);
    std::string role, secret, extra;
    if (!(fields >> role)) continue;  // blank
    if (!(fields >> secret) || (fields >> extra) || (role != "read" && role != "admin")) {
      *error = "line " + std::to_string(number) + ": expected '<read|admin> <token>'";
      return false;
    }
    if (secret.size() < 16) {
      *error = "line " + std::to_string(number) + ": a token needs at least 16 characters";
      return false;
    }
    tokens->push_back({role == "admin" ? Role::kAdmin : Role::kRead, secret});
  }
  if (tokens->empty()) {
    *error = "no token in the file";
    return false;
  }
  return true;
}

Role RequiredRole(const std::string& method) {
  static const char* const kAdminMethods[] = {"/fusion.v1.FusionMap/ResetMap",
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

bool ValidateSecurity(const fusion::v1::SecurityConfig& security, std::string* error) {
  const auto fail = [error](const std::string& field, const std::string& why) {
    *error = "security." + field + ": " + why;
    return false;
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
  return true;
}

std::shared_ptr<grpc::ServerCredentials> ServerCredentialsFor(
    const fusion::v1::SecurityConfig& security, std::string* error) {
  if (security.tls_cert_file().empty()) return grpc::InsecureServerCredentials();
  grpc::SslServerCredentialsOptions options(
      security.tls_client_ca_file().empty()
          ? GRPC_SSL_DONT_REQUEST_CLIENT_CERTIFICATE
          : GRPC_SSL_REQUEST_AND_REQUIRE_CLIENT_CERTIFICATE_AND_VERIFY);
  grpc::SslServerCredentialsOptions::PemKeyCertPair pair;
  if (!ReadFile(security.tls_key_file(), &pair.private_key, error) ||
      !ReadFile(security.tls_cert_file(), &pair.cert_chain, error)) {
    return nullptr;
  }
  options.pem_key_cert_pairs.push_back(std::move(pair));
  if (!security.tls_client_ca_file().empty() &&
      !ReadFile(security.tls_client_ca_file(), &options.pem_root_certs, error)) {
    return nullptr;
  }
  auto credentials = grpc::SslServerCredentials(options);
  if (!security.tokens_file().empty()) {
    std::string text;
    std::vector<Token> tokens;
    if (!ReadFile(security.tokens_file(), &text, error)) return nullptr;
    if (!ParseTokens(text, &tokens, error)) {
      *error = security.tokens_file() + ": " + *error;
      return nullptr;
    }
    credentials->SetAuthMetadataProcessor(std::make_shared<TokenAuthProcessor>(std::move(tokens)));
  }
  return credentials;
}

bool ReflectionEnabled(const fusion::v1::SecurityConfig& security) {
  return security.has_reflection() ? security.reflection() : security.tokens_file().empty();
}

}  // namespace fusion::service
