// What fusionctl's commands share: the channel (TLS, bearer token), deadlines, failure
// reports, argument parsing, state names.
#include <chrono>
#include <cstdlib>
#include <fstream>
#include <iterator>
#include <sstream>

#include "fusionctl.h"

namespace fusionctl {
namespace {

fusion::Status ReadFile(const std::string& what, const std::string& path,
                                 std::string* contents) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream text;
  text << in.rdbuf();
  if (!in) return fusion::Status::Error("cannot read " + what + " '" + path + "'");
  *contents = text.str();
  return fusion::Status::Ok();
}

void FromEnvironment(const char* name, std::string* value) {
  const char* env = std::getenv(name);
  if (value->empty() && env != nullptr) *value = env;
}

}  // namespace

void ApplyEnvironment(ConnectionOptions* options) {
  FromEnvironment("FUSION_TLS_CA", &options->tls_ca_path);
  FromEnvironment("FUSION_TLS_CERT", &options->tls_cert_path);
  FromEnvironment("FUSION_TLS_KEY", &options->tls_key_path);
  FromEnvironment("FUSION_TOKEN_FILE", &options->token_file_path);
}

fusion::Status CheckConnectionOptions(const ConnectionOptions& options) {
  if (options.tls_cert_path.empty() != options.tls_key_path.empty()) {
    return fusion::Status::Error("--tls-cert and --tls-key go together");
  }
  if (!options.tls_cert_path.empty() && options.tls_ca_path.empty()) {
    return fusion::Status::Error("--tls-cert and --tls-key need --tls-ca");
  }
  return fusion::Status::Ok();
}

fusion::Status ReadBearerToken(const std::string& path, std::string* token) {
  std::string contents;
  if (auto s = ReadFile("token file", path, &contents); !s.ok()) return s;
  const std::string line = contents.substr(0, contents.find('\n'));
  const char* kSpace = " \t\r\n\f\v";
  const auto first = line.find_first_not_of(kSpace);
  if (first == std::string::npos) {
    return fusion::Status::Error("token file '" + path +
                                          "' has no token on its first line");
  }
  *token = line.substr(first, line.find_last_not_of(kSpace) - first + 1);
  return fusion::Status::Ok();
}

fusion::Status MakeChannel(const ConnectionOptions& options,
                                    std::shared_ptr<grpc::Channel>* channel) {
  if (options.tls_ca_path.empty()) {
    *channel = grpc::CreateChannel(options.server, grpc::InsecureChannelCredentials());
    return fusion::Status::Ok();
  }
  grpc::SslCredentialsOptions ssl;
  if (auto s = ReadFile("--tls-ca", options.tls_ca_path, &ssl.pem_root_certs); !s.ok()) return s;
  if (!options.tls_cert_path.empty()) {
    if (auto s = ReadFile("--tls-cert", options.tls_cert_path, &ssl.pem_cert_chain); !s.ok()) {
      return s;
    }
    if (auto s = ReadFile("--tls-key", options.tls_key_path, &ssl.pem_private_key); !s.ok()) {
      return s;
    }
  }
  *channel = grpc::CreateChannel(options.server, grpc::SslCredentials(ssl));
  return fusion::Status::Ok();
}

void AddBearerToken(const std::string& token, grpc::ClientContext* context) {
  if (!token.empty()) context->AddMetadata("authorization", "Bearer " + token);
}

void PrepareCall(const Context& ctx, grpc::ClientContext* context, double timeout_s) {
  if (timeout_s > 0) {
    context->set_deadline(std::chrono::system_clock::now() +
                          std::chrono::milliseconds(static_cast<long>(timeout_s * 1000)));
  }
  AddBearerToken(ctx.bearer_token, context);
}

int Failed(const Context& ctx, const grpc::Status& status) {
  const std::string name = StatusCodeName(status.error_code());
  const std::string& server = ctx.connection.server;
  std::string detail = status.error_message();
  if (!status.error_details().empty()) detail += " (" + status.error_details() + ")";
  if (status.error_code() == grpc::StatusCode::UNAVAILABLE) {
    return fusion::clients::Fail(kTool,
                                 "cannot reach fusiond at " + server + ": " + name + ": " + detail);
  }
  if (status.error_code() == grpc::StatusCode::DEADLINE_EXCEEDED) {
    std::ostringstream seconds;
    seconds << ctx.timeout_s;
    return fusion::clients::Fail(kTool, "deadline exceeded: fusiond at " + server +
                                            " did not answer within " + seconds.str() +
                                            " s (--timeout): " + name + ": " + detail);
  }
  return fusion::clients::Fail(kTool, "fusiond at " + server + ": " + name + ": " + detail);
}

bool ParsePoint(const std::vector<std::string>& args, std::size_t at, fusion::v1::Point* p) {
  double x, y, z;
  if (at + 3 > args.size() || !fusion::clients::ParseFinite(args[at], &x) ||
      !fusion::clients::ParseFinite(args[at + 1], &y) ||
      !fusion::clients::ParseFinite(args[at + 2], &z)) {
    return false;
  }
  p->set_x(x);
  p->set_y(y);
  p->set_z(z);
  return true;
}

bool OptionUint(const Args& args, const std::string& name, unsigned long long fallback,
                unsigned long long* value) {
  const std::string text = args.Get(name);
  if (text.empty() && args.options.count(name) == 0) {
    *value = fallback;
    return true;
  }
  std::uint64_t parsed = 0;
  if (!fusion::clients::ParseUint(name, text, &parsed).ok()) return false;
  *value = parsed;
  return true;
}

const char* StateName(fusion::v1::VoxelState s) {
  switch (s) {
    case fusion::v1::VOXEL_STATE_OCCUPIED:
      return "occupied";
    case fusion::v1::VOXEL_STATE_FREE:
      return "free";
    default:
      return "unknown";
  }
}

}  // namespace fusionctl
