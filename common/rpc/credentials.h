// common/rpc/credentials.h: transport security and caller identity for every gRPC connection.
// Servers: TLS when given a certificate and key (PEM), mutual TLS when also given the CA that
// signs client certificates. Clients: TLS with the CA that signs the server's certificate (and a
// client certificate for mutual TLS), and a bearer token sent as "authorization" metadata with
// every call (an interceptor, so it works on plaintext loopback and in-process channels too).
#pragma once

#include <grpcpp/grpcpp.h>
#include <grpcpp/support/client_interceptor.h>

#include <memory>
#include <string>
#include <vector>

#include "absl/status/statusor.h"

namespace instascene::rpc {

struct TlsServerOptions {
  std::string cert_file, key_file;  // PEM; both or neither (neither = plaintext)
  std::string client_ca_file;       // PEM CA bundle: clients must present a certificate it signed
  bool enabled() const { return !cert_file.empty() || !key_file.empty(); }
};

struct ChannelOptions {
  std::string token;        // bearer token ("" = none)
  std::string tls_ca_file;  // PEM CA bundle that signed the server's certificate ("" = plaintext)
  std::string tls_cert_file, tls_key_file;  // the client's certificate (mutual TLS)
  std::string tls_server_name;  // the name the server's certificate must carry ("" = the host)
  int max_message_bytes = 64 << 20;
};

absl::StatusOr<std::shared_ptr<grpc::ServerCredentials>> MakeServerCredentials(
    const TlsServerOptions& tls);
// Refuses half-given options (a certificate without a key, a client certificate without TLS).
absl::Status ValidateChannelOptions(const ChannelOptions& options);
absl::StatusOr<std::shared_ptr<grpc::Channel>> Connect(const std::string& address,
                                                       const ChannelOptions& options);
// The interceptor that attaches `token` to every call of a channel (empty when token is "").
std::vector<std::unique_ptr<grpc::experimental::ClientInterceptorFactoryInterface>>
TokenInterceptors(const std::string& token);

}  // namespace instascene::rpc
