#include "services/gateway/gateway.h"

#include <httplib.h>

#include <filesystem>
#include <vector>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "common/core/status.h"
#include "instascene/v1/objects.grpc.pb.h"
#include "instascene/v1/scheduler.grpc.pb.h"
#include "instascene/v1/store.grpc.pb.h"
#include "services/gateway/http_util.h"
#include "services/gateway/routes.h"

namespace instascene::gateway {

std::string DefaultWebRoot() {
  namespace fs = std::filesystem;
  std::error_code ec;
  const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
  std::vector<fs::path> candidates;
  if (!ec) candidates.push_back(exe.parent_path().parent_path() / "web");  // installed images
  candidates.push_back(INSTASCENE_WEB_BUILD_DIR);                          // this build's bundle
  for (const fs::path& web : candidates)
    if (fs::is_regular_file(web / "index.html", ec)) return web.string();
  return "";
}

namespace {

// HOST and PORT of HOST:PORT (port 0: any free port).
absl::Status ParseListen(const std::string& listen, std::string* host, int* port) {
  const size_t colon = listen.rfind(':');
  if (colon == std::string::npos || !absl::SimpleAtoi(listen.substr(colon + 1), port) ||
      *port < 0 || *port > 65535)
    return absl::InvalidArgumentError(
        absl::StrCat("gateway address '", listen.substr(0, 80), "': expected HOST:PORT"));
  *host = listen.substr(0, colon);
  return absl::OkStatus();
}

// httplib's own refusals (no route, body over the limit, malformed request) in the same shape
// as the API's errors.
void SendHttplibError(const httplib::Request&, httplib::Response& res) {
  if (!res.body.empty()) return;
  const int status = res.status;
  if (status == 413)
    SendError(res,
              grpc::Status(grpc::StatusCode::RESOURCE_EXHAUSTED,
                           "request body over the gateway's limit (uploads: chunks with "
                           "Content-Type application/octet-stream)"),
              413);
  else if (status == 404)
    SendError(res, grpc::Status(grpc::StatusCode::NOT_FOUND, "no such endpoint (docs/SERVICES.md)"),
              404);
  else
    SendError(res, grpc::Status(grpc::StatusCode::INVALID_ARGUMENT, "malformed HTTP request"),
              status);
}

// The server's thread pool, body limit, socket options and error shape.
void ConfigureServer(const GatewayOptions& options, httplib::Server& http) {
  const int threads = options.threads;
  http.new_task_queue = [threads] { return new httplib::ThreadPool(threads); };
  http.set_payload_max_length(static_cast<size_t>(options.max_body_bytes));
  // SO_REUSEADDR only: a second gateway on a busy port fails instead of sharing it.
  http.set_socket_options([](socket_t sock) {
    int yes = 1;
    setsockopt(sock, SOL_SOCKET, SO_REUSEADDR, reinterpret_cast<const void*>(&yes), sizeof(yes));
  });
  http.set_error_handler(SendHttplibError);
}

}  // namespace

absl::StatusOr<std::unique_ptr<Gateway>> Gateway::Start(const GatewayOptions& options,
                                                        std::shared_ptr<grpc::Channel> scheduler,
                                                        std::shared_ptr<grpc::Channel> store,
                                                        std::shared_ptr<grpc::Channel> objects) {
  std::string host;
  int port = -1;
  RETURN_IF_ERROR(ParseListen(options.listen, &host, &port));
  if (options.max_body_bytes <= 0 || options.threads < 1)
    return absl::InvalidArgumentError("gateway: max_body_bytes and threads must be positive");
  auto stubs = std::make_shared<Stubs>();
  stubs->scheduler = v1::Scheduler::NewStub(scheduler);
  stubs->store = v1::ContentStore::NewStub(store);
  stubs->objects = v1::Objects::NewStub(objects);
  std::unique_ptr<Gateway> gateway(new Gateway());
  gateway->server_ = std::make_unique<httplib::Server>();
  httplib::Server& http = *gateway->server_;
  ConfigureServer(options, http);
  AddRoutes(http, stubs);
  AddSceneUploadRoutes(http, stubs);
  AddHttpMetrics(http);
  if (!options.web_root.empty()) {
    http.set_file_extension_and_mimetype_mapping("wasm", "application/wasm");
    http.set_file_extension_and_mimetype_mapping("mjs", "text/javascript");
    if (!http.set_mount_point("/", options.web_root))
      return absl::NotFoundError(
          absl::StrCat("gateway: web UI folder '", options.web_root, "' does not exist"));
    gateway->serves_ui_ = true;
  }
  const int bound =
      port == 0 ? http.bind_to_any_port(host) : (http.bind_to_port(host, port) ? port : -1);
  if (bound <= 0)
    return absl::UnavailableError(absl::StrCat("gateway: cannot listen on ", options.listen));
  gateway->address_ = absl::StrCat(host, ":", bound);
  gateway->thread_ = std::thread([&http] { http.listen_after_bind(); });
  return gateway;
}

Gateway::~Gateway() {
  if (server_) server_->stop();
  if (thread_.joinable()) thread_.join();
}

}  // namespace instascene::gateway
