// How a client reaches fusiond: the address, TLS files and a bearer token file (flags with
// FUSION_* environment fallbacks), and the one place a channel is made from them (rpc.cc), so
// every tool that speaks gRPC to fusiond connects the same way.
#pragma once

#include <grpcpp/grpcpp.h>

#include <memory>
#include <string>

#include "fusion/core/status.h"

namespace fusionctl {

struct ConnectionOptions {
  std::string server;           // HOST:PORT
  std::string tls_ca_path;      // PEM root certificates; non-empty: TLS
  std::string tls_cert_path;    // PEM client certificate (mutual TLS), with tls_key_path
  std::string tls_key_path;     // PEM private key of tls_cert_path
  std::string token_file_path;  // first line: the bearer token sent with every call
};

// The FUSION_TLS_CA, FUSION_TLS_CERT, FUSION_TLS_KEY and FUSION_TOKEN_FILE values for the
// fields still empty (flags win over the environment).
void ApplyEnvironment(ConnectionOptions* options);
// Checks the combination: a client certificate and its key go together, and both need --tls-ca.
fusion::Status CheckConnectionOptions(const ConnectionOptions& options);
// The first line of `path` with surrounding whitespace removed; an error if the file cannot be
// read or the line is empty.
fusion::Status ReadBearerToken(const std::string& path, std::string* token);
// A channel to options.server: SslCredentials (roots from tls_ca_path, the client key pair when
// given) with TLS, insecure without. Errors: a TLS file that cannot be read.
fusion::Status MakeChannel(const ConnectionOptions& options,
                                    std::shared_ptr<grpc::Channel>* channel);
// Adds "authorization: Bearer <token>" to a call; nothing for an empty token.
void AddBearerToken(const std::string& token, grpc::ClientContext* context);

}  // namespace fusionctl
