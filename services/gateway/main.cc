// instascene-gateway: the HTTP/JSON gateway alone, in front of services reached by address (the
// scheduler; the store and the Objects service where they run elsewhere). Callers' tokens pass
// through; the gateway itself holds none.
#include <CLI/CLI.hpp>

#include <cstdio>

#include "common/core/file_io.h"
#include "common/metrics/metrics.h"
#include "common/rpc/credentials.h"
#include "common/rpc/server.h"
#include "services/gateway/gateway.h"

int main(int argc, char** argv) {
  using namespace instascene;
  CLI::App app{"instascene-gateway: HTTP/JSON and Server-Sent Events in front of the services"};
  gateway::GatewayOptions options;
  std::string scheduler, store, objects, ready_file;
  rpc::ChannelOptions channel;
  app.add_option("--listen", options.listen, "host:port to serve HTTP on (port 0 = any free)")
      ->capture_default_str();
  app.add_option("--scheduler", scheduler, "The scheduler's address")->required();
  app.add_option("--store", store, "The store service's address (default: --scheduler)");
  app.add_option("--objects", objects, "The Objects service's address (default: --scheduler)");
  app.add_option("--max-body-bytes", options.max_body_bytes, "Largest request body")
      ->capture_default_str();
  app.add_option("--threads", options.threads, "Concurrent requests (an event stream holds one)")
      ->capture_default_str();
  app.add_option("--tls-ca", channel.tls_ca_file, "TLS towards the services: their CA (PEM)");
  app.add_option("--tls-client-cert", channel.tls_cert_file,
                 "Mutual TLS: this gateway's certificate");
  app.add_option("--tls-client-key", channel.tls_key_file, "Mutual TLS: this gateway's key");
  std::string web_root, metrics_listen;
  app.add_option("--metrics", metrics_listen,
                 "Serve Prometheus /metrics (HTTP requests by route and code, durations) at "
                 "HOST:PORT (default: off)");
  app.add_option("--web-root", web_root,
                 "The web UI's bundle to serve at / (default: BIN/../web when present; 'none' = "
                 "the API only)");
  app.add_option("--ready-file", ready_file,
                 "Write the bound address here once serving (with --metrics, a second line "
                 "metrics=HOST:PORT)");
  CLI11_PARSE(app, argc, argv);
  options.web_root = web_root.empty() ? gateway::DefaultWebRoot() : web_root;
  if (options.web_root == "none") options.web_root.clear();
  rpc::BlockShutdownSignals();
  auto connect = [&](const std::string& address) { return rpc::Connect(address, channel); };
  auto fail = [](const absl::Status& s) {
    std::fprintf(stderr, "instascene-gateway: error: %s\n", s.ToString().c_str());
    return 1;
  };
  auto to_scheduler = connect(scheduler);
  if (!to_scheduler.ok()) return fail(to_scheduler.status());
  auto to_store = store.empty() ? to_scheduler : connect(store);
  auto to_objects = objects.empty() ? to_scheduler : connect(objects);
  if (!to_store.ok()) return fail(to_store.status());
  if (!to_objects.ok()) return fail(to_objects.status());
  std::unique_ptr<metrics::Endpoint> metrics_endpoint;
  if (!metrics_listen.empty()) {
    auto endpoint = metrics::Endpoint::Start(metrics_listen);
    if (!endpoint.ok()) return fail(endpoint.status());
    metrics_endpoint = std::move(*endpoint);
  }
  auto server = gateway::Gateway::Start(options, *to_scheduler, *to_store, *to_objects);
  if (!server.ok()) return fail(server.status());
  std::printf("instascene-gateway at http://%s/api/v1/\n", (*server)->address().c_str());
  if ((*server)->serves_ui()) std::printf("web UI at http://%s/\n", (*server)->address().c_str());
  std::fflush(stdout);
  if (!ready_file.empty()) {
    std::string ready = (*server)->address() + "\n";
    if (metrics_endpoint) ready += "metrics=" + metrics_endpoint->address() + "\n";
    if (absl::Status s = WriteFileAtomically(ready_file, ready); !s.ok()) return fail(s);
  }
  rpc::WaitForShutdownSignal();
  server->reset();
  return 0;
}
