#include "services/node/node.h"

#include <filesystem>
#include <fstream>
#include <mutex>

#include <spdlog/spdlog.h>

#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "common/core/file_io.h"
#include "common/core/status.h"
#include "common/metrics/metrics.h"
#include "common/metrics/rpc_metrics.h"
#include "common/rpc/server.h"
#include "common/store/blob_store_uri.h"
#include "services/gateway/gateway.h"
#include "services/pipeline/memory.h"
#include "services/scheduler/postgres_queue_store.h"
#include "services/scheduler/scheduler_metrics.h"
#include "services/scheduler/scheduler_service.h"
#include "services/scheduler/sqlite_queue_store.h"
#include "services/store/remote_blob_store.h"
#include "services/store/store_service.h"

namespace instascene::node {
namespace fs = std::filesystem;

absl::Status NodeOptions::Validate() const {
  if (!run_store && store.empty())
    return absl::InvalidArgumentError(
        "no store: run one here or give --store HOST:PORT (the store service) or s3://...");
  if (run_store && !store.empty() && !store::IsBlobStoreUri(store))
    return absl::InvalidArgumentError(absl::StrCat(
        "--store '", store.substr(0, 80),
        "': the store service keeps its blobs in file:DIR or s3://BUCKET/PREFIX?endpoint=..."));
  if (!run_scheduler && scheduler_address.empty() && !workers.empty())
    return absl::InvalidArgumentError(
        "workers need a scheduler: run one here or give --scheduler ADDR");
  if (!run_store && !run_scheduler && workers.empty())
    return absl::InvalidArgumentError("nothing to run");
  if (lease_seconds < 2) return absl::InvalidArgumentError("--lease-seconds must be >= 2");
  if (drain_seconds < 0) return absl::InvalidArgumentError("--drain-seconds must be >= 0");
  if (memory_budget_bytes < -1)
    return absl::InvalidArgumentError("--memory-budget-bytes must be >= 0 (or -1: no limit)");
  if (index_cache_bytes < 0) return absl::InvalidArgumentError("--index-cache-bytes must be >= 0");
  if (!(retention_hours >= 0 && retention_hours <= 24 * 3650))
    return absl::InvalidArgumentError("--retention-hours must be in [0, 87600]");
  if (no_auth && !auth_tokens.empty())
    return absl::InvalidArgumentError("--no-auth and --auth-tokens contradict each other");
  RETURN_IF_ERROR(rpc::ValidateChannelOptions(peer_tls));
  return store_options.Validate();
}

namespace {

absl::StatusOr<std::unique_ptr<scheduler::JobQueue>> OpenQueue(
    const NodeOptions& options, const scheduler::QueueOptions& queue_options) {
  const std::string& q = options.queue;
  if (q.empty())
    return scheduler::OpenSqliteJobQueue((fs::path(options.data_dir) / "jobs.db").string(),
                                         queue_options);
  if (absl::StartsWith(q, "sqlite:"))
    return scheduler::OpenSqliteJobQueue(q.substr(7), queue_options);
  if (absl::StartsWith(q, "postgres://") || absl::StartsWith(q, "postgresql://"))
    return scheduler::OpenPostgresJobQueue(q, queue_options);
  return absl::InvalidArgumentError(
      absl::StrCat("--queue: expected sqlite:PATH or postgres://..., not '", q.substr(0, 80), "'"));
}

// Store contents and the data directory's disk, read at scrape time.
std::shared_ptr<prometheus::Collectable> StoreCollector(store::BlobStore* store, bool has_store,
                                                        const std::string& data_dir) {
  return std::make_shared<metrics::CallbackCollectable>([store, has_store, data_dir] {
    std::vector<prometheus::MetricFamily> out;
    if (has_store) {
      if (absl::StatusOr<store::StoreStats> s = store->Stats(); s.ok()) {
        auto add = [&](const char* name, const char* help, double value) {
          prometheus::MetricFamily f = metrics::GaugeFamily(name, help);
          metrics::AddGauge(&f, {}, value);
          out.push_back(std::move(f));
        };
        add("instascene_store_bytes", "Bytes of committed blobs", s->total_bytes);
        add("instascene_store_blobs", "Committed blobs", s->blob_count);
        add("instascene_store_partial_upload_bytes", "Bytes of interrupted, resumable uploads",
            s->partial_bytes);
        add("instascene_store_partial_uploads", "Interrupted, resumable uploads",
            s->partial_uploads);
      }
    }
    std::error_code ec;
    const fs::space_info space = fs::space(data_dir, ec);
    if (!ec) {
      prometheus::MetricFamily capacity = metrics::GaugeFamily(
          "instascene_data_dir_capacity_bytes", "Size of the file system holding --data");
      metrics::AddGauge(&capacity, {}, static_cast<double>(space.capacity));
      prometheus::MetricFamily available = metrics::GaugeFamily(
          "instascene_data_dir_available_bytes", "Free bytes on the file system holding --data");
      metrics::AddGauge(&available, {}, static_cast<double>(space.available));
      out.push_back(std::move(capacity));
      out.push_back(std::move(available));
    }
    return out;
  });
}

// The authenticator of this node (null with --no-auth). The default token file is created on first
// start with one admin token, written beside it for the CLI on this machine.
absl::StatusOr<std::shared_ptr<auth::Authenticator>> OpenAuthenticator(const NodeOptions& options) {
  if (options.no_auth) {
    spdlog::warn("authentication is off (--no-auth): every caller is an admin");
    return std::shared_ptr<auth::Authenticator>();
  }
  const fs::path auth_dir = fs::path(options.data_dir) / "auth";
  const std::string path =
      options.auth_tokens.empty() ? (auth_dir / "tokens.json").string() : options.auth_tokens;
  std::error_code ec;
  if (options.auth_tokens.empty() && !fs::exists(path, ec)) {
    ASSIGN_OR_RETURN(std::string token,
                     auth::CreateToken(path, auth::Role::kAdmin, "", "created on first start"));
    const std::string admin_file = (auth_dir / "admin.token").string();
    RETURN_IF_ERROR(auth::WriteTokenFile(admin_file, token));
    spdlog::info("first start: an admin token is in {} (the CLI on this machine finds it)",
                 admin_file);
  }
  return auth::Authenticator::FromFile(path);
}

// How this node reaches the store / scheduler services it does not host.
absl::StatusOr<rpc::ChannelOptions> PeerChannelOptions(const NodeOptions& options) {
  rpc::ChannelOptions channel = options.peer_tls;
  if (!options.token_file.empty()) {
    ASSIGN_OR_RETURN(channel.token, auth::ReadTokenFile(options.token_file));
  }
  return channel;
}

}  // namespace

absl::Status RunNode(const NodeOptions& options, const pipeline::StageRegistry& stages,
                     const std::vector<StageService>& available) {
  RETURN_IF_ERROR(options.Validate());
  std::vector<const StageService*> hosted;
  for (const std::string& name : options.workers) {
    const StageService* found = nullptr;
    std::vector<std::string> names;
    for (const StageService& s : available) {
      names.push_back(s.name);
      if (s.name == name) found = &s;
    }
    if (found == nullptr)
      return absl::InvalidArgumentError(absl::StrCat(
          "unknown worker '", name, "' (this binary runs ", absl::StrJoin(names, ", "), ")"));
    hosted.push_back(found);
  }
  rpc::BlockShutdownSignals();
  std::error_code ec;
  fs::create_directories(options.data_dir, ec);
  if (ec) return absl::UnavailableError(absl::StrCat(options.data_dir, ": ", ec.message()));
  ASSIGN_OR_RETURN(std::shared_ptr<auth::Authenticator> authenticator, OpenAuthenticator(options));
  auth::Authenticator* auth = authenticator.get();
  ASSIGN_OR_RETURN(rpc::ChannelOptions peer, PeerChannelOptions(options));
  auto connect_peer = [&peer](const std::string& address) {
    rpc::ChannelOptions c = peer;
    return rpc::Connect(address, c);
  };

  // The store: local (served here) or remote.
  std::unique_ptr<store::BlobStore> owned_store;
  if (options.run_store || store::IsBlobStoreUri(options.store)) {
    const std::string uri = options.store.empty()
                                ? "file:" + (fs::path(options.data_dir) / "store").string()
                                : options.store;
    ASSIGN_OR_RETURN(owned_store, store::OpenBlobStoreUri(uri, options.store_options));
  } else {
    ASSIGN_OR_RETURN(std::shared_ptr<grpc::Channel> store_channel, connect_peer(options.store));
    ASSIGN_OR_RETURN(owned_store, store_service::RemoteBlobStore::Connect(store_channel));
  }
  store::BlobStore* blob_store = owned_store.get();

  std::vector<grpc::Service*> services;
  std::vector<std::string> names;
  std::unique_ptr<store_service::StoreService> store_svc;
  if (options.run_store) {
    store_svc = std::make_unique<store_service::StoreService>(blob_store, auth);
    services.push_back(store_svc.get());
    names.push_back("instascene.v1.ContentStore");
  }
  std::unique_ptr<scheduler::JobQueue> queue;
  std::unique_ptr<scheduler::SchedulerService> scheduler_svc;
  if (options.run_scheduler) {
    scheduler::QueueOptions queue_options;
    queue_options.lease_ms = int64_t{options.lease_seconds} * 1000;
    queue_options.max_lease_ms = std::max(queue_options.max_lease_ms, queue_options.lease_ms);
    for (const std::string& kind : stages.Kinds()) {
      if (stages.Find(kind)->spec.partial_join) queue_options.partial_join_kinds.insert(kind);
    }
    ASSIGN_OR_RETURN(queue, OpenQueue(options, queue_options));
    scheduler::SchedulerServiceOptions scheduler_options;
    scheduler_options.rescue_interval_ms = std::min(1000, options.lease_seconds * 250);
    scheduler_options.retention_ms = static_cast<int64_t>(options.retention_hours * 3600e3);
    scheduler_options.auth = auth;
    scheduler_svc = std::make_unique<scheduler::SchedulerService>(queue.get(), blob_store, &stages,
                                                                  scheduler_options);
    services.push_back(scheduler_svc.get());
    names.push_back("instascene.v1.Scheduler");
  }
  const std::string work_dir = (fs::path(options.data_dir) / "work").string();
  // The scheduler's channel, known once the server runs (services built before ask it lazily).
  struct SchedulerChannel {
    std::mutex mutex;
    std::shared_ptr<grpc::Channel> channel;
  };
  auto scheduler_channel = std::make_shared<SchedulerChannel>();
  auto get_scheduler = [scheduler_channel]() {
    std::lock_guard<std::mutex> lock(scheduler_channel->mutex);
    return scheduler_channel->channel;
  };
  std::vector<std::unique_ptr<worker::StageWorker>> workers;
  std::vector<std::unique_ptr<grpc::Service>> stage_services;
  for (const StageService* hosted_service : hosted) {
    worker::WorkerOptions w;
    w.kinds = hosted_service->kinds;
    w.work_dir = work_dir;
    w.num_threads = options.num_threads;
    w.lease_seconds = options.lease_seconds;
    w.cache_bytes = options.cache_bytes;
    if (!options.denoiser.empty()) w.stage_settings["denoiser"] = options.denoiser;
    w.memory_budget_bytes = options.memory_budget_bytes == 0  ? pipeline::PhysicalMemoryBytes()
                            : options.memory_budget_bytes < 0 ? 0
                                                              : options.memory_budget_bytes;
    w.heartbeat_interval_ms = std::min(1000, options.lease_seconds * 1000 / 4);  // live progress
    RETURN_IF_ERROR(w.Validate(stages));
    workers.push_back(std::make_unique<worker::StageWorker>(w, blob_store, &stages));
    StageServiceContext context;
    context.worker = workers.back().get();
    context.store = blob_store;
    context.work_dir = (fs::path(work_dir) / hosted_service->name).string();
    context.scheduler = get_scheduler;
    context.index_cache_bytes = options.index_cache_bytes;
    context.auth = auth;
    stage_services.push_back(hosted_service->make(context));
    services.push_back(stage_services.back().get());
    names.push_back(hosted_service->grpc_name);
  }

  // Metrics before the server: a refused metrics address stops the node before anything runs.
  std::unique_ptr<metrics::Endpoint> metrics_endpoint;
  std::vector<std::shared_ptr<prometheus::Collectable>> collectors;
  if (!options.metrics_listen.empty()) {
    ASSIGN_OR_RETURN(metrics_endpoint, metrics::Endpoint::Start(options.metrics_listen));
    if (queue) collectors.push_back(scheduler::QueueCollector(queue.get()));
    collectors.push_back(StoreCollector(blob_store, options.run_store, options.data_dir));
    for (const auto& c : collectors) metrics_endpoint->Add(c);
  }

  rpc::ServerOptions server_options;
  server_options.listen = options.listen;
  server_options.tls = options.tls;
  server_options.interceptors = metrics::RpcMetricsInterceptors;  // call latencies by method
  server_options.max_message_bytes = static_cast<int>(
      std::min<int64_t>(options.store_options.max_batch_bytes + (1 << 20), 1 << 30));
  ASSIGN_OR_RETURN(std::unique_ptr<rpc::Server> server,
                   rpc::Server::Start(server_options, services, names));
  if (!workers.empty()) {
    // The node's own workers reach an in-process scheduler with a token valid in this process only.
    std::string process_token;
    if (auth != nullptr && options.run_scheduler) {
      ASSIGN_OR_RETURN(process_token, auth->AddProcessToken(auth::Role::kWorker));
    }
    std::shared_ptr<grpc::Channel> channel;
    if (options.run_scheduler) {
      channel = server->InProcessChannel(process_token);
    } else {
      ASSIGN_OR_RETURN(channel, connect_peer(options.scheduler_address));
    }
    {
      std::lock_guard<std::mutex> lock(scheduler_channel->mutex);
      scheduler_channel->channel = channel;
    }
    for (auto& w : workers) w->Start(channel);
  }
  std::unique_ptr<gateway::Gateway> http_gateway;
  if (!options.gateway_listen.empty()) {
    gateway::GatewayOptions gateway_options;
    gateway_options.listen = options.gateway_listen;
    gateway_options.web_root =
        options.web_root.empty() ? gateway::DefaultWebRoot() : options.web_root;
    if (gateway_options.web_root == "none") gateway_options.web_root.clear();
    const std::shared_ptr<grpc::Channel> local = server->InProcessChannel();
    ASSIGN_OR_RETURN(http_gateway, gateway::Gateway::Start(gateway_options, local, local, local));
  }
  spdlog::info("instascene node serving on {} (data {}): {}", server->address(), options.data_dir,
               absl::StrJoin(names, ", "));
  if (http_gateway) spdlog::info("HTTP gateway at http://{}/api/v1/", http_gateway->address());
  if (http_gateway && http_gateway->serves_ui())
    spdlog::info("web UI at http://{}/", http_gateway->address());
  if (metrics_endpoint) spdlog::info("metrics at http://{}/metrics", metrics_endpoint->address());
  if (!options.ready_file.empty()) {
    std::string ready = server->address() + "\n";
    if (metrics_endpoint) absl::StrAppend(&ready, "metrics=", metrics_endpoint->address(), "\n");
    if (http_gateway) absl::StrAppend(&ready, "gateway=", http_gateway->address(), "\n");
    RETURN_IF_ERROR(WriteFileAtomically(options.ready_file, ready));
  }

  const int sig = rpc::WaitForShutdownSignal();
  spdlog::info("signal {}: draining (running jobs get {} s)", sig, options.drain_seconds);
  const auto deadline = std::chrono::seconds(options.drain_seconds);
  // Workers first (they still need the scheduler to hand jobs back), then the scheduler, then RPCs.
  std::vector<std::thread> drains;
  for (auto& w : workers) drains.emplace_back([w = w.get(), deadline] { w->Drain(deadline); });
  for (std::thread& t : drains) t.join();
  if (scheduler_svc) scheduler_svc->Stop();
  http_gateway.reset();  // open event streams end
  server->Drain(std::chrono::seconds(5));
  metrics_endpoint.reset();
  if (!options.ready_file.empty()) fs::remove(options.ready_file, ec);
  spdlog::info("stopped");
  return absl::OkStatus();
}

}  // namespace instascene::node
