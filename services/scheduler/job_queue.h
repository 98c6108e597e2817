// services/scheduler/job_queue.h: the job queue core. Every policy of the queue lives here once,
// over the narrow storage interface of queue_store.h, so that each backend (SQLite now, PostgreSQL
// next) stores jobs and nothing else:
//   - submission of a whole pipeline in one transaction, idempotent by job key (a succeeded job is
//     a cached result; a failed or cancelled one is queued again);
//   - the DAG: a job is ready when all its dependencies succeeded; a fan-out job reports how many
//     items its output holds, and its completion creates one job per item of each per-item stage
//     and the join jobs that wait for all of them (in the same transaction);
//   - leases with fencing tokens, bounded by the server's maximum and persisted (heartbeats renew
//     with the granted length); expiry rescue; capped exponential backoff with jitter;
//   - failure outcomes (FailureKind): retryable, permanent (never retried), cancelled, released;
//   - cancellation and failure cascade to every dependent job; a whole scene can be cancelled;
//   - scenes as first-class things: the latest successful output of each stage.
// Time comes from an injected clock. Thread-safe.
#pragma once

#include <cstdint>
#include <memory>
#include <mutex>
#include <optional>
#include <random>
#include <set>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "common/core/clock.h"
#include "services/scheduler/queue_store.h"

namespace instascene::scheduler {

struct QueueOptions {
  int64_t lease_ms = 30000;        // lease length when a worker asks for none
  int64_t max_lease_ms = 600000;   // the longest lease a worker may ask for (longer: clamped)
  int64_t min_lease_ms = 1000;     // the shortest (shorter: clamped)
  int64_t backoff_base_ms = 1000;  // first retry delay
  int64_t backoff_cap_ms = 60000;  // delays double per attempt up to this cap
  double backoff_jitter = 0.25;    // delay *= 1 - jitter * U[0,1) (spreads retry storms)
  int64_t max_items = 10000;       // most items one fan-out job may report
  // Most unfinished (queued, leased, running) jobs one tenant's scenes may hold when a submission
  // adds jobs (0 = no limit): over it the submission is ResourceExhausted and adds nothing. Jobs
  // a fan-out creates when its source completes are not refused (max_items bounds them).
  int64_t max_unfinished_per_tenant = 0;
  uint64_t seed = 1;  // jitter and lease-token random seed
  // Join stages that run over the items that succeeded (StageSpec::partial_join): a failed or
  // cancelled per-item input is left out instead of cancelling the join. Set from the registry;
  // every scheduler of one queue must agree.
  std::set<std::string> partial_join_kinds;

  absl::Status Validate() const;
};

struct SubmitResult {
  Job job;
  bool created = false;   // false: an existing job (maybe already succeeded) was returned
  bool requeued = false;  // an existing failed or cancelled job queued again
};

struct Lease {
  Job job;
  std::string token;
  // The outputs of the job's dependencies, by dependency name.
  std::vector<std::pair<std::string, store::Digest>> inputs;
};

struct HeartbeatResult {
  bool cancel_requested = false;
  int64_t lease_expires_ms = 0;
};

// The latest successful output of one stage (one item of a per-item stage) of a scene.
struct StageOutput {
  std::string kind;
  int64_t item = -1;
  std::string job_id;
  store::Digest output;
  store::Digest scene_manifest;
  int64_t completed_ms = 0;
};

struct SceneSummary {
  std::string scene;
  store::Digest scene_manifest;      // of the most recently submitted job
  std::vector<StageOutput> outputs;  // by kind, then item
  std::vector<std::pair<std::string, int64_t>> jobs_by_state;
};

class JobQueue {
 public:
  JobQueue(std::unique_ptr<QueueStore> store, const QueueOptions& options,
           Clock* clock = RealClock());

  // Creates (or finds) every job of a pipeline in one transaction: all or nothing. Returns the
  // jobs created or found now (deferred per-item and join jobs only where their fan-out source
  // already succeeded), in dependency order.
  absl::StatusOr<std::vector<SubmitResult>> Submit(const SubmitRequest& request);
  // The next ready job of one of `kinds`, or nullopt. lease_ms 0 = the default.
  absl::StatusOr<std::optional<Lease>> LeaseNext(const std::vector<std::string>& kinds,
                                                 const std::string& worker_id,
                                                 int64_t lease_ms = 0);
  absl::StatusOr<HeartbeatResult> Heartbeat(const std::string& id, const std::string& token,
                                            const JobProgress& progress);
  // `items`: how many items the output holds, for a fan-out stage (-1 for other stages).
  absl::Status Complete(const std::string& id, const std::string& token,
                        const store::Digest& output, int64_t items = -1);
  absl::Status Fail(const std::string& id, const std::string& token, FailureKind kind,
                    const std::string& error);
  absl::StatusOr<Job> Cancel(const std::string& id);
  // Cancels every unfinished job of a scene; returns each of them as it is now (cancelled, or
  // asked to stop when held). NotFound for an unknown scene.
  absl::StatusOr<std::vector<Job>> CancelScene(const std::string& scene);
  // Deletes a scene's jobs once every one of them has ended (FailedPrecondition naming how many
  // have not: cancel the scene and wait), but those an unfinished job of another scene still
  // needs. NotFound if the scene has no jobs. Its blobs stay until the store's garbage collection
  // finds them unreachable.
  struct DeletedScene {
    int deleted = 0, kept = 0;
  };
  absl::StatusOr<DeletedScene> DeleteScene(const std::string& scene);
  absl::StatusOr<Job> Get(const std::string& id);
  absl::StatusOr<std::vector<Job>> List(const JobFilter& filter);
  absl::StatusOr<QueueStats> Stats();
  absl::StatusOr<SceneSummary> GetScene(const std::string& scene);
  // Returns expired leases to the queue (or fails / cancels them); the number handled.
  absl::StatusOr<int> RescueExpired();
  // Retention: deletes jobs finished more than `retention_ms` ago that no unfinished job depends
  // on. A pruned result is recomputed if its pipeline is submitted again. Returns how many.
  absl::StatusOr<int> PruneFinished(int64_t retention_ms);

  const QueueOptions& options() const { return options_; }

 private:
  absl::Status Apply(Job* job, JobEvent event);
  absl::StatusOr<Job> LoadHeld(QueueTx& tx, const std::string& id, const std::string& token);
  absl::StatusOr<Job> Load(QueueTx& tx, const std::string& id);
  // Creates the job or returns the existing one (re-queuing it when failed or cancelled).
  absl::StatusOr<SubmitResult> SubmitOne(QueueTx& tx, const SubmitRequest& request,
                                         const std::string& kind, const nlohmann::json& parameters,
                                         std::vector<JobDependency> dependencies,
                                         const std::string& parent, int64_t item);
  // Creates the deferred jobs of one plan of a succeeded fan-out job.
  absl::Status Expand(QueueTx& tx, const Job& source, const nlohmann::json& plan,
                      std::vector<SubmitResult>* results);
  // ResourceExhausted when a submission that added jobs leaves its scene's tenant over
  // max_unfinished_per_tenant (the caller's transaction then rolls back).
  absl::Status CheckTenantLimit(QueueTx& tx, const std::string& scene,
                                const std::vector<SubmitResult>& results);
  absl::Status RetryOrFail(QueueTx& tx, Job* job, const std::string& error, bool retryable);
  absl::Status EndCancelled(QueueTx& tx, Job* job, const std::string& why);
  // A job ended failed or cancelled: its dependents are cancelled, except partial joins, which
  // only stop waiting for it when it is one of their per-item inputs.
  absl::Status CancelDependents(QueueTx& tx, const std::string& id, const std::string& why);
  // Whether `job` may run without its input `name` (a per-item input of a partial join).
  bool MayLeaveOut(const Job& job, const std::string& name) const;
  int64_t BackoffMs(int attempts);
  std::string NewToken(int attempt);

  static constexpr int kMaxSceneJobs = 100000;  // jobs of one scene read by CancelScene, GetScene

  std::unique_ptr<QueueStore> store_;
  QueueOptions options_;
  Clock* clock_;
  std::mutex rng_mutex_;
  std::mt19937_64 rng_;
};

}  // namespace instascene::scheduler
