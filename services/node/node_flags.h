// services/node/node_flags.h: the command-line flags shared by `instascene serve` and the
// per-service binaries, and their main(). Header-only (CLI11).
#pragma once

#include <CLI/CLI.hpp>

#include <cstdio>

#include "services/node/node.h"

namespace instascene::node {

// Where the node keeps its data and serves, and where the store, the scheduler and the queue are.
inline void AddLocationFlags(CLI::App& app, NodeOptions* o, bool needs_store_address,
                             bool needs_scheduler_address) {
  app.add_option("--data", o->data_dir, "Data directory (store/, jobs.db, work/)")
      ->capture_default_str();
  app.add_option("--listen", o->listen, "host:port to serve on (port 0 = any free port)")
      ->capture_default_str();
  if (needs_store_address)
    app.add_option("--store", o->store,
                   "The store: HOST:PORT of the store service, or storage to use directly "
                   "(s3://BUCKET/PREFIX?endpoint=URL&region=R&addressing=path|virtual, "
                   "credentials from AWS_ACCESS_KEY_ID/AWS_SECRET_ACCESS_KEY or "
                   "~/.aws/credentials; or file:DIR)")
        ->required();
  else
    app.add_option("--store", o->store,
                   "Where the store keeps its blobs: file:DIR (default DATA/store) or "
                   "s3://BUCKET/PREFIX?endpoint=URL&region=R&addressing=path|virtual "
                   "(credentials from AWS_ACCESS_KEY_ID/AWS_SECRET_ACCESS_KEY or "
                   "~/.aws/credentials, never from flags)");
  if (needs_scheduler_address)
    app.add_option("--scheduler", o->scheduler_address, "Address of the scheduler service")
        ->required();
  app.add_option(
      "--queue", o->queue,
      "Job queue storage: sqlite:PATH (default DATA/jobs.db) or postgres://HOST[:PORT]/DB "
      "(password from PGPASSWORD or ~/.pgpass)");
}

// The scheduler's queue policy: retention, a tenant's bound, leases, draining.
inline void AddSchedulerFlags(CLI::App& app, NodeOptions* o) {
  app.add_option(
         "--retention-hours", o->retention_hours,
         "Scheduler: prune jobs finished longer ago than this (0 = keep for ever); a pruned "
         "result is recomputed when its pipeline is submitted again (job records only: "
         "`instascene gc` removes the blobs no job reaches)")
      ->capture_default_str();
  app.add_option("--max-unfinished-jobs-per-tenant", o->max_unfinished_per_tenant,
                 "Scheduler: most queued, leased and running jobs one tenant may hold; a "
                 "submission over it is RESOURCE_EXHAUSTED and adds nothing (0 = no limit; "
                 "admins' scenes without a tenant are not limited)")
      ->capture_default_str();
  app.add_option("--lease-seconds", o->lease_seconds, "Job lease length in seconds")
      ->capture_default_str();
  app.add_option("--drain-seconds", o->drain_seconds,
                 "On SIGTERM, how long running jobs may take before they are handed back")
      ->capture_default_str();
}

// Workers' resources, the denoiser, the gateway, metrics and the ready file.
inline void AddRuntimeFlags(CLI::App& app, NodeOptions* o) {
  app.add_option("--threads", o->num_threads, "Threads per job (0 = all cores)");
  app.add_option(
         "--cache-bytes", o->cache_bytes,
         "Per worker: budget of the input cache under DATA/work, LRU-evicted (0 = unlimited)")
      ->capture_default_str();
  app.add_option("--index-cache-bytes", o->index_cache_bytes,
                 "Objects service: memory budget of the loaded scene indexes (LRU; the newest is "
                 "always kept)")
      ->capture_default_str();
  app.add_option("--ready-file", o->ready_file,
                 "Write the bound address here once serving (removed at exit); with --metrics a "
                 "second line metrics=HOST:PORT");
  app.add_option("--denoiser", o->denoiser,
                 "Generation workers: the diffusion prior's denoiser, grpc://HOST:PORT (a "
                 "Denoiser service) or onnx:FILE.json (a model file run in the worker) "
                 "(default: none; complete jobs with prior diffusion then fail)");
  app.add_option("--gateway", o->gateway_listen,
                 "Serve the HTTP/JSON gateway (/api/v1, Server-Sent Events) at HOST:PORT in front "
                 "of this node's services (port 0 = any free port; default: off)");
  app.add_option("--web-root", o->web_root,
                 "With --gateway: the web UI's bundle to serve at / (default: BIN/../web, else "
                 "this build's bundle; 'none' = the API only)");
  app.add_option("--memory-budget-bytes", o->memory_budget_bytes,
                 "Workers: the most one job may allocate; a job whose stage estimates more fails "
                 "with RESOURCE_EXHAUSTED before it runs (0 = the machine's physical memory, -1 = "
                 "no limit)")
      ->capture_default_str();
  app.add_option("--metrics", o->metrics_listen,
                 "Serve Prometheus metrics at http://HOST:PORT/metrics (port 0 = any free port; "
                 "default: off)");
}

// Authentication and TLS, as a server and towards the services it reaches.
inline void AddSecurityFlags(CLI::App& app, NodeOptions* o) {
  app.add_option("--auth-tokens", o->auth_tokens,
                 "Token file every call is checked against (default DATA/auth/tokens.json, "
                 "created on first start with an admin token in DATA/auth/admin.token); edit it "
                 "with `instascene token`");
  app.add_flag("--no-auth", o->no_auth,
               "Accept every call without a token, as an admin (trusted networks only)");
  app.add_option("--token-file", o->token_file,
                 "This node's token (role worker or admin) for the --store / --scheduler it "
                 "reaches by address");
  app.add_option("--tls-cert", o->tls.cert_file, "TLS: this server's certificate chain (PEM)");
  app.add_option("--tls-key", o->tls.key_file, "TLS: this server's private key (PEM)");
  app.add_option("--tls-client-ca", o->tls.client_ca_file,
                 "Mutual TLS: only clients with a certificate signed by this CA (PEM) connect");
  app.add_option("--tls-ca", o->peer_tls.tls_ca_file,
                 "TLS towards --store / --scheduler: the CA that signed their certificates (PEM)");
  app.add_option("--tls-client-cert", o->peer_tls.tls_cert_file,
                 "Mutual TLS towards --store / --scheduler: this node's certificate (PEM)");
  app.add_option("--tls-client-key", o->peer_tls.tls_key_file,
                 "Mutual TLS towards --store / --scheduler: this node's private key (PEM)");
}

// The store's limits.
inline void AddStoreLimitFlags(CLI::App& app, NodeOptions* o) {
  app.add_option("--max-blob-bytes", o->store_options.max_blob_bytes,
                 "Largest blob the store accepts")
      ->capture_default_str();
  app.add_option("--upload-ttl-seconds", o->store_options.upload_ttl_seconds,
                 "Interrupted uploads untouched for this long are removed (filesystem store; 0 = "
                 "never)")
      ->capture_default_str()
      ->check(CLI::NonNegativeNumber);
  app.add_option("--tenant-quota-bytes", o->store_options.tenant_quota_bytes,
                 "Store service: the most bytes of blobs granted to one tenant (its uploads and "
                 "its jobs' outputs); a new upload over it is RESOURCE_EXHAUSTED (0 = no limit)")
      ->capture_default_str()
      ->check(CLI::NonNegativeNumber);
}

inline void AddNodeFlags(CLI::App& app, NodeOptions* o, bool needs_store_address,
                         bool needs_scheduler_address) {
  AddLocationFlags(app, o, needs_store_address, needs_scheduler_address);
  AddSchedulerFlags(app, o);
  AddRuntimeFlags(app, o);
  AddSecurityFlags(app, o);
  AddStoreLimitFlags(app, o);
}

// main() of a per-service binary: `stages` are the stages it knows, `services` the stage services
// it can host (all of them run unless --workers is given).
inline int NodeMain(int argc, char** argv, const char* description, NodeOptions options,
                    bool needs_store_address, bool needs_scheduler_address,
                    const pipeline::StageRegistry& stages,
                    const std::vector<StageService>& services = {}) {
  CLI::App app{description};
  AddNodeFlags(app, &options, needs_store_address, needs_scheduler_address);
  CLI11_PARSE(app, argc, argv);
  const absl::Status status = RunNode(options, stages, services);
  if (!status.ok()) {
    std::fprintf(stderr, "%s: error: %s\n", app.get_name().c_str(), status.ToString().c_str());
    return 1;
  }
  return 0;
}

}  // namespace instascene::node
