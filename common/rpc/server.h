// common/rpc/server.h: runs a gRPC server with an explicit lifecycle
// STARTING -> SERVING -> DRAINING -> STOPPED, reported through the standard grpc.health.v1 service
// (per registered service name and overall ""), server reflection, message-size limits, optional
// TLS (common/rpc/credentials.h), interceptors (the node's RPC metrics,
// common/metrics/rpc_metrics.h), and a graceful drain against a deadline (stop accepting, let
// in-flight calls finish, then cancel). Also: waiting for SIGTERM / SIGINT. Thread-safe.
#pragma once

#include <grpcpp/grpcpp.h>
#include <grpcpp/support/server_interceptor.h>

#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "common/rpc/credentials.h"

namespace instascene::rpc {

struct ServerOptions {
  std::string listen = "127.0.0.1:50051";  // host:port; port 0 = pick a free one
  int max_message_bytes = 64 << 20;        // per message, both directions
  TlsServerOptions tls;                    // none = plaintext
  // Server interceptors (e.g. metrics::RpcMetricsInterceptors); null = none.
  std::function<
      std::vector<std::unique_ptr<grpc::experimental::ServerInterceptorFactoryInterface>>()>
      interceptors;
};

class Server {
 public:
  // Services must outlive the server. Names are the full proto service names (for health).
  static absl::StatusOr<std::unique_ptr<Server>> Start(
      const ServerOptions& options, const std::vector<grpc::Service*>& services,
      const std::vector<std::string>& service_names);
  ~Server();

  std::string address() const { return address_; }  // with the bound port
  // An in-process channel to this server (no sockets), for services hosted in the same process;
  // every call carries `token` when one is given.
  std::shared_ptr<grpc::Channel> InProcessChannel(const std::string& token = "");
  // Health NOT_SERVING, then Shutdown with the deadline: in-flight calls get until then.
  void Drain(std::chrono::milliseconds deadline);

 private:
  Server() = default;
  std::unique_ptr<grpc::Server> server_;
  std::vector<std::string> names_;
  std::string address_;
  bool stopped_ = false;
};

// Blocks SIGTERM / SIGINT in the calling thread (call before starting other threads, so every
// thread inherits the mask), then WaitForShutdownSignal() returns the signal that arrived.
void BlockShutdownSignals();
int WaitForShutdownSignal();

// A client channel with the same message limits.
std::shared_ptr<grpc::Channel> Connect(const std::string& address,
                                       int max_message_bytes = 64 << 20);

}  // namespace instascene::rpc
