#include "services/node/node.h"

#include <filesystem>
#include <fstream>

#include <spdlog/spdlog.h>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "common/core/status.h"
#include "common/rpc/server.h"
#include "services/decomposition/decomposition_service.h"
#include "services/scheduler/scheduler_service.h"
#include "services/scheduler/sqlite_job_queue.h"
#include "services/store/remote_blob_store.h"
#include "services/store/store_service.h"
#include "services/training/training_service.h"
#include "services/worker/stage_worker.h"

namespace instascene::node {
namespace fs = std::filesystem;

absl::Status NodeOptions::Validate() const {
  if (!run_store && store_address.empty())
    return absl::InvalidArgumentError("no store: run one here or give --store ADDR");
  if (!run_scheduler && scheduler_address.empty() && (run_decomposition || run_training))
    return absl::InvalidArgumentError(
        "workers need a scheduler: run one here or give --scheduler ADDR");
  if (!run_store && !run_scheduler && !run_decomposition && !run_training)
    return absl::InvalidArgumentError("nothing to run");
  if (lease_seconds < 2) return absl::InvalidArgumentError("--lease-seconds must be >= 2");
  if (drain_seconds < 0) return absl::InvalidArgumentError("--drain-seconds must be >= 0");
  return store_options.Validate();
}

absl::Status RunNode(const NodeOptions& options) {
  RETURN_IF_ERROR(options.Validate());
  rpc::BlockShutdownSignals();
  std::error_code ec;
  fs::create_directories(options.data_dir, ec);
  if (ec) return absl::UnavailableError(absl::StrCat(options.data_dir, ": ", ec.message()));

  // The store: local (served here) or remote.
  std::unique_ptr<store::FilesystemBlobStore> local_store;
  std::unique_ptr<store::BlobStore> remote_store;
  store::BlobStore* blob_store = nullptr;
  if (options.run_store) {
    ASSIGN_OR_RETURN(local_store,
                     store::FilesystemBlobStore::Open(
                         (fs::path(options.data_dir) / "store").string(), options.store_options));
    blob_store = local_store.get();
  } else {
    ASSIGN_OR_RETURN(remote_store,
                     store_service::RemoteBlobStore::Connect(rpc::Connect(options.store_address)));
    blob_store = remote_store.get();
  }

  std::vector<grpc::Service*> services;
  std::vector<std::string> names;
  std::unique_ptr<store_service::StoreService> store_svc;
  if (options.run_store) {
    store_svc = std::make_unique<store_service::StoreService>(blob_store);
    services.push_back(store_svc.get());
    names.push_back("instascene.v1.ContentStore");
  }
  std::unique_ptr<scheduler::SqliteJobQueue> queue;
  std::unique_ptr<scheduler::SchedulerService> scheduler_svc;
  if (options.run_scheduler) {
    scheduler::QueueOptions queue_options;
    queue_options.lease_ms = int64_t{options.lease_seconds} * 1000;
    ASSIGN_OR_RETURN(queue, scheduler::SqliteJobQueue::Open(
                                (fs::path(options.data_dir) / "jobs.db").string(), queue_options));
    scheduler::SchedulerServiceOptions scheduler_options;
    scheduler_options.rescue_interval_ms = std::min(1000, options.lease_seconds * 250);
    scheduler_svc =
        std::make_unique<scheduler::SchedulerService>(queue.get(), blob_store, scheduler_options);
    services.push_back(scheduler_svc.get());
    names.push_back("instascene.v1.Scheduler");
  }
  const std::string work_dir = (fs::path(options.data_dir) / "work").string();
  auto make_worker =
      [&](std::vector<std::string> kinds) -> absl::StatusOr<std::unique_ptr<worker::StageWorker>> {
    worker::WorkerOptions w;
    w.kinds = std::move(kinds);
    w.work_dir = work_dir;
    w.num_threads = options.num_threads;
    w.lease_seconds = options.lease_seconds;
    w.cache_bytes = options.cache_bytes;
    w.heartbeat_interval_ms = std::min(1000, options.lease_seconds * 1000 / 4);  // live progress
    RETURN_IF_ERROR(w.Validate());
    return std::make_unique<worker::StageWorker>(w, blob_store);
  };
  std::unique_ptr<worker::StageWorker> decomposition_worker, training_worker;
  std::unique_ptr<decomposition::DecompositionService> decomposition_svc;
  std::unique_ptr<training::TrainingService> training_svc;
  if (options.run_decomposition) {
    ASSIGN_OR_RETURN(decomposition_worker, make_worker({"decompose"}));
    decomposition_svc =
        std::make_unique<decomposition::DecompositionService>(decomposition_worker.get());
    services.push_back(decomposition_svc.get());
    names.push_back("instascene.v1.Decomposition");
  }
  if (options.run_training) {
    ASSIGN_OR_RETURN(training_worker, make_worker({"train", "segment"}));
    training_svc = std::make_unique<training::TrainingService>(
        blob_store, (fs::path(work_dir) / "query").string(), training_worker.get());
    services.push_back(training_svc.get());
    names.push_back("instascene.v1.Training");
  }

  rpc::ServerOptions server_options;
  server_options.listen = options.listen;
  server_options.max_message_bytes = static_cast<int>(
      std::min<int64_t>(options.store_options.max_batch_bytes + (1 << 20), 1 << 30));
  ASSIGN_OR_RETURN(std::unique_ptr<rpc::Server> server,
                   rpc::Server::Start(server_options, services, names));
  if (decomposition_worker || training_worker) {
    std::shared_ptr<grpc::Channel> scheduler_channel =
        options.run_scheduler ? server->InProcessChannel()
                              : rpc::Connect(options.scheduler_address);
    if (decomposition_worker) decomposition_worker->Start(scheduler_channel);
    if (training_worker) training_worker->Start(scheduler_channel);
  }
  spdlog::info("instascene node serving on {} (data {}): {}", server->address(), options.data_dir,
               absl::StrJoin(names, ", "));
  if (!options.ready_file.empty()) {
    const std::string temp = options.ready_file + ".tmp";
    std::ofstream(temp) << server->address() << "\n";
    fs::rename(temp, options.ready_file, ec);
  }

  const int sig = rpc::WaitForShutdownSignal();
  spdlog::info("signal {}: draining (running jobs get {} s)", sig, options.drain_seconds);
  const auto deadline = std::chrono::seconds(options.drain_seconds);
  // Workers first (they still need the scheduler to hand jobs back), then the scheduler, then RPCs.
  std::vector<std::thread> drains;
  for (worker::StageWorker* w : {decomposition_worker.get(), training_worker.get()}) {
    if (w) drains.emplace_back([w, deadline] { w->Drain(deadline); });
  }
  for (std::thread& t : drains) t.join();
  if (scheduler_svc) scheduler_svc->Stop();
  server->Drain(std::chrono::seconds(5));
  if (!options.ready_file.empty()) fs::remove(options.ready_file, ec);
  spdlog::info("stopped");
  return absl::OkStatus();
}

}  // namespace instascene::node
