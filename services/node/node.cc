#include "services/node/node.h"

#include <filesystem>
#include <fstream>
#include <mutex>

#include <spdlog/spdlog.h>

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
#include "services/scheduler/queue_uri.h"
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
  if (max_unfinished_per_tenant < 0)
    return absl::InvalidArgumentError("--max-unfinished-jobs-per-tenant must be >= 0");
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
  return scheduler::OpenJobQueueUri(q, queue_options);
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

// The stage services this node hosts, by name. InvalidArgument names an unknown one.
absl::StatusOr<std::vector<const StageService*>> HostedServices(
    const NodeOptions& options, const std::vector<StageService>& available) {
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
  return hosted;
}

// The scheduler's channel, known once the server runs (services built before ask it lazily).
struct SchedulerChannel {
  std::mutex mutex;
  std::shared_ptr<grpc::Channel> channel;
};

// Everything a node runs. Members are destroyed in reverse order: the gateway and the server
// before the services, the workers and the queue they use, the store last.
class Node {
 public:
  Node(const NodeOptions& options, const pipeline::StageRegistry& stages)
      : options_(options), stages_(stages) {}

  absl::Status Open();  // authenticator, peer channel options, store
  absl::Status AddScheduler();
  absl::Status AddStageWorkers(const std::vector<const StageService*>& hosted);
  absl::Status Serve();  // metrics, gRPC server, workers started, gateway, ready file
  void Drain();

 private:
  absl::StatusOr<std::shared_ptr<grpc::Channel>> ConnectPeer(const std::string& address) const {
    rpc::ChannelOptions c = peer_;
    return rpc::Connect(address, c);
  }
  absl::Status StartWorkers();
  void Announce() const;

  const NodeOptions& options_;
  const pipeline::StageRegistry& stages_;
  std::shared_ptr<auth::Authenticator> authenticator_;
  rpc::ChannelOptions peer_;
  std::unique_ptr<store::BlobStore> store_;
  std::vector<grpc::Service*> services_;
  std::vector<std::string> names_;
  std::unique_ptr<store_service::StoreService> store_service_;
  std::unique_ptr<scheduler::JobQueue> queue_;
  std::unique_ptr<scheduler::SchedulerService> scheduler_service_;
  std::shared_ptr<SchedulerChannel> scheduler_channel_ = std::make_shared<SchedulerChannel>();
  std::vector<std::unique_ptr<worker::StageWorker>> workers_;
  std::vector<std::unique_ptr<grpc::Service>> stage_services_;
  std::unique_ptr<metrics::Endpoint> metrics_endpoint_;
  std::vector<std::shared_ptr<prometheus::Collectable>> collectors_;
  std::unique_ptr<rpc::Server> server_;
  std::unique_ptr<gateway::Gateway> gateway_;
};

absl::Status Node::Open() {
  std::error_code ec;
  fs::create_directories(options_.data_dir, ec);
  if (ec) return absl::UnavailableError(absl::StrCat(options_.data_dir, ": ", ec.message()));
  ASSIGN_OR_RETURN(authenticator_, OpenAuthenticator(options_));
  ASSIGN_OR_RETURN(peer_, PeerChannelOptions(options_));
  // The store: local (served here) or remote.
  if (options_.run_store || store::IsBlobStoreUri(options_.store)) {
    const std::string uri = options_.store.empty()
                                ? "file:" + (fs::path(options_.data_dir) / "store").string()
                                : options_.store;
    ASSIGN_OR_RETURN(store_, store::OpenBlobStoreUri(uri, options_.store_options));
  } else {
    ASSIGN_OR_RETURN(std::shared_ptr<grpc::Channel> store_channel, ConnectPeer(options_.store));
    ASSIGN_OR_RETURN(store_, store_service::RemoteBlobStore::Connect(store_channel));
  }
  if (options_.run_store) {
    store_service_ =
        std::make_unique<store_service::StoreService>(store_.get(), authenticator_.get());
    services_.push_back(store_service_.get());
    names_.push_back("instascene.v1.ContentStore");
  }
  return absl::OkStatus();
}

absl::Status Node::AddScheduler() {
  if (!options_.run_scheduler) return absl::OkStatus();
  scheduler::QueueOptions queue_options;
  queue_options.lease_ms = int64_t{options_.lease_seconds} * 1000;
  queue_options.max_lease_ms = std::max(queue_options.max_lease_ms, queue_options.lease_ms);
  queue_options.max_unfinished_per_tenant = options_.max_unfinished_per_tenant;
  for (const std::string& kind : stages_.Kinds()) {
    if (stages_.Find(kind)->spec.partial_join) queue_options.partial_join_kinds.insert(kind);
  }
  ASSIGN_OR_RETURN(queue_, OpenQueue(options_, queue_options));
  scheduler::SchedulerServiceOptions scheduler_options;
  scheduler_options.rescue_interval_ms = std::min(1000, options_.lease_seconds * 250);
  scheduler_options.retention_ms = static_cast<int64_t>(options_.retention_hours * 3600e3);
  scheduler_options.auth = authenticator_.get();
  scheduler_service_ = std::make_unique<scheduler::SchedulerService>(queue_.get(), store_.get(),
                                                                     &stages_, scheduler_options);
  services_.push_back(scheduler_service_.get());
  names_.push_back("instascene.v1.Scheduler");
  return absl::OkStatus();
}

absl::Status Node::AddStageWorkers(const std::vector<const StageService*>& hosted) {
  const std::string work_dir = (fs::path(options_.data_dir) / "work").string();
  auto get_scheduler = [scheduler_channel = scheduler_channel_]() {
    std::lock_guard<std::mutex> lock(scheduler_channel->mutex);
    return scheduler_channel->channel;
  };
  for (const StageService* hosted_service : hosted) {
    worker::WorkerOptions w;
    w.kinds = hosted_service->kinds;
    w.work_dir = work_dir;
    w.num_threads = options_.num_threads;
    w.lease_seconds = options_.lease_seconds;
    w.cache_bytes = options_.cache_bytes;
    if (!options_.denoiser.empty()) w.stage_settings["denoiser"] = options_.denoiser;
    w.memory_budget_bytes = options_.memory_budget_bytes == 0  ? pipeline::PhysicalMemoryBytes()
                            : options_.memory_budget_bytes < 0 ? 0
                                                               : options_.memory_budget_bytes;
    w.heartbeat_interval_ms = std::min(1000, options_.lease_seconds * 1000 / 4);  // live progress
    RETURN_IF_ERROR(w.Validate(stages_));
    workers_.push_back(std::make_unique<worker::StageWorker>(w, store_.get(), &stages_));
    StageServiceContext context;
    context.worker = workers_.back().get();
    context.store = store_.get();
    context.scheduler = get_scheduler;
    context.index_cache_bytes = options_.index_cache_bytes;
    context.auth = authenticator_.get();
    stage_services_.push_back(hosted_service->make(context));
    services_.push_back(stage_services_.back().get());
    names_.push_back(hosted_service->grpc_name);
  }
  return absl::OkStatus();
}

// The node's own workers reach an in-process scheduler with a token valid in this process only,
// or the remote scheduler.
absl::Status Node::StartWorkers() {
  if (workers_.empty()) return absl::OkStatus();
  std::string process_token;
  if (authenticator_ != nullptr && options_.run_scheduler) {
    ASSIGN_OR_RETURN(process_token, authenticator_->AddProcessToken(auth::Role::kWorker));
  }
  std::shared_ptr<grpc::Channel> channel;
  if (options_.run_scheduler) {
    channel = server_->InProcessChannel(process_token);
  } else {
    ASSIGN_OR_RETURN(channel, ConnectPeer(options_.scheduler_address));
  }
  {
    std::lock_guard<std::mutex> lock(scheduler_channel_->mutex);
    scheduler_channel_->channel = channel;
  }
  for (auto& w : workers_) w->Start(channel);
  return absl::OkStatus();
}

absl::Status Node::Serve() {
  // Metrics before the server: a refused metrics address stops the node before anything runs.
  if (!options_.metrics_listen.empty()) {
    ASSIGN_OR_RETURN(metrics_endpoint_, metrics::Endpoint::Start(options_.metrics_listen));
    if (queue_) collectors_.push_back(scheduler::QueueCollector(queue_.get()));
    collectors_.push_back(StoreCollector(store_.get(), options_.run_store, options_.data_dir));
    for (const auto& c : collectors_) metrics_endpoint_->Add(c);
  }
  rpc::ServerOptions server_options;
  server_options.listen = options_.listen;
  server_options.tls = options_.tls;
  server_options.interceptors = metrics::RpcMetricsInterceptors;  // call latencies by method
  server_options.max_message_bytes = static_cast<int>(
      std::min<int64_t>(options_.store_options.max_batch_bytes + (1 << 20), 1 << 30));
  ASSIGN_OR_RETURN(server_, rpc::Server::Start(server_options, services_, names_));
  RETURN_IF_ERROR(StartWorkers());
  if (!options_.gateway_listen.empty()) {
    gateway::GatewayOptions gateway_options;
    gateway_options.listen = options_.gateway_listen;
    gateway_options.web_root =
        options_.web_root.empty() ? gateway::DefaultWebRoot() : options_.web_root;
    if (gateway_options.web_root == "none") gateway_options.web_root.clear();
    const std::shared_ptr<grpc::Channel> local = server_->InProcessChannel();
    ASSIGN_OR_RETURN(gateway_, gateway::Gateway::Start(gateway_options, local, local, local));
  }
  Announce();
  if (options_.ready_file.empty()) return absl::OkStatus();
  std::string ready = server_->address() + "\n";
  if (metrics_endpoint_) absl::StrAppend(&ready, "metrics=", metrics_endpoint_->address(), "\n");
  if (gateway_) absl::StrAppend(&ready, "gateway=", gateway_->address(), "\n");
  return WriteFileAtomically(options_.ready_file, ready);
}

void Node::Announce() const {
  spdlog::info("instascene node serving on {} (data {}): {}", server_->address(), options_.data_dir,
               absl::StrJoin(names_, ", "));
  if (gateway_) spdlog::info("HTTP gateway at http://{}/api/v1/", gateway_->address());
  if (gateway_ && gateway_->serves_ui()) spdlog::info("web UI at http://{}/", gateway_->address());
  if (metrics_endpoint_) spdlog::info("metrics at http://{}/metrics", metrics_endpoint_->address());
}

// Workers first (they still need the scheduler to hand jobs back), then the scheduler, then RPCs.
void Node::Drain() {
  const auto deadline = std::chrono::seconds(options_.drain_seconds);
  std::vector<std::thread> drains;
  for (auto& w : workers_) drains.emplace_back([w = w.get(), deadline] { w->Drain(deadline); });
  for (std::thread& t : drains) t.join();
  if (scheduler_service_) scheduler_service_->Stop();
  gateway_.reset();  // open event streams end
  server_->Drain(std::chrono::seconds(5));
  metrics_endpoint_.reset();
  std::error_code ec;
  if (!options_.ready_file.empty()) fs::remove(options_.ready_file, ec);
}

}  // namespace

absl::Status RunNode(const NodeOptions& options, const pipeline::StageRegistry& stages,
                     const std::vector<StageService>& available) {
  RETURN_IF_ERROR(options.Validate());
  ASSIGN_OR_RETURN(const std::vector<const StageService*> hosted,
                   HostedServices(options, available));
  rpc::BlockShutdownSignals();
  Node node(options, stages);
  RETURN_IF_ERROR(node.Open());
  RETURN_IF_ERROR(node.AddScheduler());
  RETURN_IF_ERROR(node.AddStageWorkers(hosted));
  RETURN_IF_ERROR(node.Serve());
  const int sig = rpc::WaitForShutdownSignal();
  spdlog::info("signal {}: draining (running jobs get {} s)", sig, options.drain_seconds);
  node.Drain();
  spdlog::info("stopped");
  return absl::OkStatus();
}

}  // namespace instascene::node
