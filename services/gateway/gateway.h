// services/gateway/gateway.h: HTTP/JSON in front of the gRPC services, for web front ends and
// anything that speaks HTTP (cpp-httplib from Debian; JSON is protobuf's canonical proto3 JSON
// mapping of the same messages). Every /api/v1 call forwards the caller's bearer token
// ("Authorization" header; for EventSource, which cannot set headers, `access_token=` on /events)
// to the services, which authorize it as any gRPC call. Errors are the gRPC status as JSON,
// {"error": {"code": 404, "status": "NOT_FOUND", "message": "..."}}, with the HTTP status of
// Google's API mapping. Request bodies are bounded (--max-body-bytes); a slow or vanished browser
// holds one gateway thread, never a worker. Endpoints: docs/SERVICES.md "HTTP gateway".
// Thread-safe.
#pragma once

#include <grpcpp/grpcpp.h>

#include <memory>
#include <string>
#include <thread>

#include "absl/status/statusor.h"

namespace httplib {
class Server;
}

namespace instascene::gateway {

struct GatewayOptions {
  std::string listen = "127.0.0.1:8080";      // host:port (port 0 = any free port)
  int64_t max_body_bytes = int64_t{8} << 20;  // request bodies (upload chunks: 4 MiB by default)
  int threads = 16;  // concurrent requests (an open event stream holds one)
  // The web UI's bundle (clients/web, built into BUILD/web), served at "/"; empty = API only.
  std::string web_root;
};

// The web UI bundle: BIN/../web beside the running binary (as the container images lay it out),
// else this build's BUILD/web; "" when neither exists.
std::string DefaultWebRoot();

class Gateway {
 public:
  // The channels must reach the scheduler, the store and the Objects service (they may be one).
  static absl::StatusOr<std::unique_ptr<Gateway>> Start(const GatewayOptions& options,
                                                        std::shared_ptr<grpc::Channel> scheduler,
                                                        std::shared_ptr<grpc::Channel> store,
                                                        std::shared_ptr<grpc::Channel> objects);
  ~Gateway();  // stops serving: open event streams end
  std::string address() const { return address_; }
  bool serves_ui() const { return serves_ui_; }

 private:
  Gateway() = default;
  std::unique_ptr<httplib::Server> server_;
  std::thread thread_;
  std::string address_;
  bool serves_ui_ = false;
};

}  // namespace instascene::gateway
