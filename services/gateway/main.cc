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

namespace {

using namespace instascene;

struct GatewayFlags {
  gateway::GatewayOptions options;
  std::string scheduler, store, objects, ready_file, web_root, metrics_listen;
  rpc::ChannelOptions channel;
};

void AddFlags(CLI::App& app, GatewayFlags* f) {
  app.add_option("--listen", f->options.listen, "host:port to serve HTTP on (port 0 = any free)")
      ->capture_default_str();
  app.add_option("--scheduler", f->scheduler, "The scheduler's address")->required();
  app.add_option("--store", f->store, "The store service's address (default: --scheduler)");
  app.add_option("--objects", f->objects, "The Objects service's address (default: --scheduler)");
  app.add_option("--max-body-bytes", f->options.max_body_bytes, "Largest request body")
      ->capture_default_str();
  app.add_option("--threads", f->options.threads, "Concurrent requests (an event stream holds one)")
      ->capture_default_str();
  app.add_option("--tls-ca", f->channel.tls_ca_file, "TLS towards the services: their CA (PEM)");
  app.add_option("--tls-client-cert", f->channel.tls_cert_file,
                 "Mutual TLS: this gateway's certificate");
  app.add_option("--tls-client-key", f->channel.tls_key_file, "Mutual TLS: this gateway's key");
  app.add_option("--metrics", f->metrics_listen,
                 "Serve Prometheus /metrics (HTTP requests by route and code, durations) at "
                 "HOST:PORT (default: off)");
  app.add_option("--web-root", f->web_root,
                 "The web UI's bundle to serve at / (default: BIN/../web when present; 'none' = "
                 "the API only)");
  app.add_option("--ready-file", f->ready_file,
                 "Write the bound address here once serving (with --metrics, a second line "
                 "metrics=HOST:PORT)");
}

int Fail(const absl::Status& s) {
  std::fprintf(stderr, "instascene-gateway: error: %s\n", s.ToString().c_str());
  return 1;
}

// Connects to the services, starts the metrics endpoint and the gateway, announces the address
// (stdout and --ready-file) and serves until SIGTERM or SIGINT.
int Serve(GatewayFlags& f) {
  f.options.web_root = f.web_root.empty() ? gateway::DefaultWebRoot() : f.web_root;
  if (f.options.web_root == "none") f.options.web_root.clear();
  rpc::BlockShutdownSignals();
  auto connect = [&](const std::string& address) { return rpc::Connect(address, f.channel); };
  auto to_scheduler = connect(f.scheduler);
  if (!to_scheduler.ok()) return Fail(to_scheduler.status());
  auto to_store = f.store.empty() ? to_scheduler : connect(f.store);
  auto to_objects = f.objects.empty() ? to_scheduler : connect(f.objects);
  if (!to_store.ok()) return Fail(to_store.status());
  if (!to_objects.ok()) return Fail(to_objects.status());
  std::unique_ptr<metrics::Endpoint> metrics_endpoint;
  if (!f.metrics_listen.empty()) {
    auto endpoint = metrics::Endpoint::Start(f.metrics_listen);
    if (!endpoint.ok()) return Fail(endpoint.status());
    metrics_endpoint = std::move(*endpoint);
  }
  auto server = gateway::Gateway::Start(f.options, *to_scheduler, *to_store, *to_objects);
  if (!server.ok()) return Fail(server.status());
  std::printf("instascene-gateway at http://%s/api/v1/\n", (*server)->address().c_str());
  if ((*server)->serves_ui()) std::printf("web UI at http://%s/\n", (*server)->address().c_str());
  std::fflush(stdout);
  if (!f.ready_file.empty()) {
    std::string ready = (*server)->address() + "\n";
    if (metrics_endpoint) ready += "metrics=" + metrics_endpoint->address() + "\n";
    if (absl::Status s = WriteFileAtomically(f.ready_file, ready); !s.ok()) return Fail(s);
  }
  rpc::WaitForShutdownSignal();
  server->reset();
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"instascene-gateway: HTTP/JSON and Server-Sent Events in front of the services"};
  GatewayFlags flags;
  AddFlags(app, &flags);
  CLI11_PARSE(app, argc, argv);
  return Serve(flags);
}
