// services/worker/stage_worker.h: the pull loop every stage service runs. It leases jobs of its
// kinds from the scheduler, fetches the scene and every named input from the store (cached by
// digest under work_dir), runs the stage through the registry (services/pipeline) with progress
// and cooperative cancellation, uploads the output directory as a manifest and completes the job
// (with its items, for a fan-out stage) — or fails it, permanently when the input itself is bad. A
// heartbeat thread extends the lease, reports progress with an ETA, and stops the stage when
// cancellation is requested or the lease is lost. Thread-safe.
#pragma once

#include <grpcpp/grpcpp.h>

#include <atomic>
#include <condition_variable>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "common/auth/authenticator.h"
#include "common/core/cancel.h"
#include "common/store/blob_store.h"
#include "instascene/v1/scheduler.grpc.pb.h"
#include "services/pipeline/registry.h"

namespace instascene::worker {

struct WorkerOptions {
  std::string worker_id;                    // "" = <hostname>-<pid>-<kinds>
  std::vector<std::string> kinds;           // job kinds to lease (runnable in the registry)
  std::string work_dir;                     // scene/input cache and job scratch space
  int num_threads = 0;                      // per job; 0 = all cores
  int poll_interval_ms = 300;               // wait between empty lease attempts
  int heartbeat_interval_ms = 1000;         // progress + lease extension period
  int lease_seconds = 0;                    // requested lease length; 0 = the scheduler's default
  int64_t cache_bytes = int64_t{20} << 30;  // input cache budget, LRU-evicted (0 = unlimited)
  std::map<std::string, std::string> stage_settings;  // given to every stage (StageContext)
  // The most one job may allocate (bytes): a job whose stage estimates more fails permanently with
  // RESOURCE_EXHAUSTED before it runs (services/pipeline/memory.h). 0 = no limit.
  int64_t memory_budget_bytes = 0;

  absl::Status Validate(const pipeline::StageRegistry& stages) const;
};

class StageWorker {
 public:
  // `store` and `stages` must outlive the worker.
  StageWorker(WorkerOptions options, store::BlobStore* store,
              const pipeline::StageRegistry* stages);
  ~StageWorker();

  // Starts the lease loop against the scheduler behind `scheduler`.
  void Start(std::shared_ptr<grpc::Channel> scheduler);
  // Stops leasing, gives the running job until `deadline` to finish, then cancels it and hands it
  // back to the queue (retryable failure). Returns when the loop has ended.
  void Drain(std::chrono::milliseconds deadline);

  const std::string& worker_id() const { return options_.worker_id; }
  std::string current_job() const;
  int64_t succeeded() const { return succeeded_; }
  // Waits (at most `timeout`) until at least `count` jobs succeeded: the scheduler records a
  // success before the worker counts it, so a caller that saw the job succeed awaits the count.
  bool AwaitSucceeded(int64_t count, std::chrono::milliseconds timeout) const;
  int64_t failed() const { return failed_; }
  bool draining() const { return draining_; }

 private:
  void Loop();
  void RunJob(const v1::LeaseJobResponse& lease);
  // How a job ended on this worker.
  struct JobOutcome {
    absl::Status status;      // the stage's
    store::Digest output;     // its output manifest (status ok)
    int64_t items = -1;       // per-item stages: how many items it made
    bool lease_lost = false;  // the scheduler no longer knew the lease
    bool cancel_requested = false;
    bool handed_back = false;  // cancelled by Drain
  };
  // Completes or fails the job at the scheduler (nothing when its lease was lost); returns the
  // outcome's metric label.
  const char* ReportOutcome(const v1::LeaseJobResponse& lease, const JobOutcome& outcome,
                            double seconds);
  using ProgressFn = std::function<void(const pipeline::StageProgress&)>;
  // The job's scene and inputs, from the worker's input cache (fetched on a miss; the cache
  // evicted to its budget first): their directories into `context`; returns the scene's digest.
  absl::StatusOr<store::Digest> FetchInputs(const v1::LeaseJobResponse& lease,
                                            const ProgressFn& progress,
                                            pipeline::StageContext* context);
  // The job directory's output manifest (with the job, scene and items), uploaded.
  absl::StatusOr<store::Digest> UploadOutput(const v1::Job& job, const std::string& job_dir,
                                             const store::Digest& scene, int64_t items);
  // Fetches inputs, runs the stage, uploads the output manifest.
  absl::Status Execute(const v1::LeaseJobResponse& lease, const std::string& job_dir,
                       CancelFlag* cancel, const ProgressFn& progress, store::Digest* output,
                       int64_t* items);
  bool SleepUnlessDraining(std::chrono::milliseconds duration);

  WorkerOptions options_;
  std::unique_ptr<v1::Scheduler::Stub> scheduler_;
  store::BlobStore* store_;
  const pipeline::StageRegistry* stages_;
  std::thread thread_;
  mutable std::mutex mutex_;
  std::condition_variable wake_;
  std::string current_job_;
  CancelFlag* current_cancel_ = nullptr;  // of the running job, under mutex_
  bool handed_back_ = false;              // the running job was cancelled by Drain
  std::atomic<bool> draining_{false};
  std::atomic<int64_t> succeeded_{0}, failed_{0};
  mutable std::condition_variable counted_;  // notified (under mutex_) when succeeded_ grows
};

// The WorkerStatus every stage service reports (worker may be null: a service without a worker).
void FillWorkerStatus(const StageWorker* worker, const std::vector<std::string>& kinds,
                      v1::WorkerStatus* out);
// GetWorkerStatus of a stage service: monitoring, for admins only (auth null = off).
grpc::Status AnswerWorkerStatus(auth::Authenticator* auth, grpc::ServerContext* context,
                                const StageWorker* worker, const std::vector<std::string>& kinds,
                                v1::WorkerStatus* out);

}  // namespace instascene::worker
