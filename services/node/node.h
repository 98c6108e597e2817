// services/node/node.h: one process hosting any subset of the services: the store, the scheduler
// and stage services (a worker leasing some stages' jobs + its gRPC adapter), all on one port.
// The node links no stage library: each binary's main registers the stages it knows (runnable or
// specs only) and the stage services it can host (stage_services.h), and passes them in.
// `instascene serve` runs everything (the embedded default: filesystem store + SQLite queue under
// --data); `instascene-store`, `instascene-scheduler`, `instascene-decomposition` and
// `instascene-training` run one role each and reach the others by address.
//
// Lifecycle: STARTING -> SERVING (health SERVING, ready file written) -> on SIGTERM/SIGINT DRAINING
// (workers stop leasing; running jobs get --drain-seconds to finish, then are handed back to the
// queue) -> STOPPED. Nothing acknowledged is lost: the queue and the store are durable.
#pragma once

#include <functional>
#include <memory>
#include <string>
#include <vector>

#include <grpcpp/grpcpp.h>

#include "absl/status/status.h"
#include "common/auth/authenticator.h"
#include "common/rpc/credentials.h"
#include "common/store/blob_store.h"
#include "services/pipeline/registry.h"
#include "services/worker/stage_worker.h"

namespace instascene::node {

struct NodeOptions {
  std::string data_dir = "instascene-data";  // store/, jobs.db, work/ live here
  std::string listen = "127.0.0.1:50051";    // host:port (port 0 = any free port)
  bool run_store = true;
  bool run_scheduler = true;
  std::vector<std::string> workers;  // stage services to run here, by name (see StageService)
  // The store. With run_store: where its blobs live, "file:DIR" (default: DATA/store) or
  // "s3://BUCKET/PREFIX?endpoint=...&region=..." (common/store/blob_store_uri.h). Without: the
  // store service's HOST:PORT, or a storage URI to use directly (every process that opens the
  // same bucket and prefix shares the store; no store service needed between them).
  std::string store;
  // The job queue's storage: "" or "sqlite:PATH" (embedded default: DATA/jobs.db), or a PostgreSQL
  // URI "postgres://HOST[:PORT]/DB?..." (scale-out; several schedulers may share it). Passwords
  // come from PGPASSWORD or ~/.pgpass, never from this flag.
  std::string queue;
  std::string scheduler_address;             // where the scheduler is when !run_scheduler
  double retention_hours = 0;                // scheduler: prune jobs finished longer ago (0 = keep)
  int64_t max_unfinished_per_tenant = 5000;  // scheduler: a tenant's queued/running jobs (0 = any)
  int lease_seconds = 30;                    // job lease length; heartbeats renew it every lease/4
  int drain_seconds = 30;                    // SIGTERM: how long running jobs may take to finish
  int num_threads = 0;                       // per job; 0 = all cores
  int64_t cache_bytes = int64_t{20} << 30;   // per worker: input cache budget (0 = unlimited)
  int64_t index_cache_bytes = int64_t{4} << 30;  // Objects service: loaded scene indexes
  std::string ready_file;  // written with the bound address once serving ("" = none)
  // Prometheus /metrics on this host:port ("" = off): RPC latencies, the queue (with a
  // scheduler), the store (with a store), workers' jobs, the data directory's disk space.
  std::string metrics_listen;
  // The HTTP/JSON gateway (services/gateway) on this host:port ("" = off), in front of this
  // node's services (in-process channel).
  std::string gateway_listen;
  std::string web_root;  // the gateway's web UI bundle ("" = beside the binary, "none" = no UI)
  // Generation workers: the diffusion prior's denoiser (grpc://HOST:PORT or onnx:FILE.json; "" =
  // none, and complete jobs asking for prior "diffusion" fail).
  std::string denoiser;
  // Workers: the most one job may allocate; a larger estimate fails the job before it runs
  // (RESOURCE_EXHAUSTED). 0 = the machine's physical memory; -1 = no limit.
  int64_t memory_budget_bytes = 0;
  // Authentication (docs/SERVICES.md): the token file every call is checked against ("" =
  // DATA/auth/tokens.json; created on first start with an admin token in DATA/auth/admin.token
  // when it is the default and absent). no_auth turns checking off (a trusted network only).
  std::string auth_tokens;
  bool no_auth = false;
  // This node's own credential towards the store / scheduler it reaches by address (a worker or
  // admin token, `instascene token create --role worker`; "" = none).
  std::string token_file;
  rpc::TlsServerOptions tls;     // TLS on the gRPC listener (none = plaintext)
  rpc::ChannelOptions peer_tls;  // TLS towards --store / --scheduler (tls_* fields only)
  store::StoreOptions store_options;

  absl::Status Validate() const;
};

// What a stage service's adapter is built with.
struct StageServiceContext {
  const worker::StageWorker* worker = nullptr;  // null when the service leases no stage
  store::BlobStore* store = nullptr;
  // The scheduler's channel once the node serves (in-process, or --scheduler's address); null
  // before. Services that ask the scheduler (the Objects service resolving scene names) call it
  // per request.
  std::function<std::shared_ptr<grpc::Channel>()> scheduler;
  int64_t index_cache_bytes = 0;        // NodeOptions::index_cache_bytes
  auth::Authenticator* auth = nullptr;  // null = authentication off
};

// A stage service a node can host: a worker leasing `kinds` and the gRPC adapter around it.
struct StageService {
  std::string name;       // as --workers names it: "decomposition", "training", ...
  std::string grpc_name;  // full gRPC service name (health, reflection)
  std::vector<std::string> kinds;
  std::function<std::unique_ptr<grpc::Service>(const StageServiceContext& context)> make;
};

// Runs until SIGTERM or SIGINT, then drains. `stages` must hold every stage the scheduler accepts
// (specs suffice) and the runnable stages of the hosted services. Call from main before starting
// other threads.
absl::Status RunNode(const NodeOptions& options, const pipeline::StageRegistry& stages,
                     const std::vector<StageService>& services);

}  // namespace instascene::node
