// services/scheduler/queue_store.h: the narrow storage interface behind the job queue. A backend
// (SQLite: sqlite_queue_store.h; PostgreSQL next) stores jobs and answers a handful of queries
// inside transactions; every policy (readiness, retries, backoff, cascades, fan-out, leases) lives
// once in the backend-free core (job_queue.h). Implementations are thread-safe; a QueueTx is used
// by one thread for the duration of one Transact call.
#pragma once

#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "services/scheduler/job.h"

namespace instascene::scheduler {

struct JobFilter {
  std::string scene;              // "" = all
  std::string scene_prefix;       // "" = all; else only scenes whose name starts with it (a tenant)
  std::optional<JobState> state;  // unset = all
  std::vector<std::string> ids;   // non-empty: exactly these (NotFound if one is missing)
  int limit = 100;                // newest first
  int64_t before_seq = 0;  // pagination: only jobs older than this Job::seq (0 = from newest)
};

struct QueueStats {
  std::vector<std::pair<std::string, int64_t>> jobs_by_state;
  int64_t scenes = 0;
  int64_t oldest_queued_age_ms = 0;
  // Per stage (job kind): jobs in each state (kinds with jobs only), and the age of the oldest
  // queued job (kinds with queued jobs only). For the metrics (instascene_jobs,
  // instascene_queue_oldest_queued_age_seconds).
  struct StageState {
    std::string stage, state;
    int64_t jobs = 0;
  };
  std::vector<StageState> jobs_by_stage;
  std::vector<std::pair<std::string, int64_t>> oldest_queued_age_ms_by_stage;
};

// One transaction's view of the stored jobs.
class QueueTx {
 public:
  virtual ~QueueTx() = default;
  virtual absl::StatusOr<std::optional<Job>> Get(const std::string& id) = 0;
  // A new job (its dependencies with it). AlreadyExists if the id is taken.
  virtual absl::Status Insert(const Job& job) = 0;
  // Every mutable field of an existing job (dependencies never change).
  virtual absl::Status Update(const Job& job) = 0;
  // Ids of the jobs that list `id` as a dependency.
  virtual absl::StatusOr<std::vector<std::string>> Dependents(const std::string& id) = 0;
  // The next job to lease among queued jobs of `kinds` with pending == 0 and not_before <= now:
  // highest priority, then the scene with the fewest held jobs, then the scene leased least
  // recently, then submission order.
  virtual absl::StatusOr<std::optional<std::string>> NextReady(
      const std::vector<std::string>& kinds, int64_t now_ms) = 0;
  // Records that `scene` was just served (fairness).
  virtual absl::Status TouchScene(const std::string& scene, int64_t now_ms) = 0;
  // Held (leased or running) jobs whose lease expired before now.
  virtual absl::StatusOr<std::vector<std::string>> Expired(int64_t now_ms) = 0;
  virtual absl::StatusOr<std::vector<Job>> List(const JobFilter& filter) = 0;
  // Unfinished (queued, leased, running) jobs of the scenes whose name starts with
  // `scene_prefix` (a tenant's "acme:"), this transaction's own changes included. A backend where
  // transactions of several processes run concurrently (PostgreSQL) first takes a lock on the
  // prefix held to the transaction's end, so two submissions of one tenant count one after the
  // other.
  virtual absl::StatusOr<int64_t> CountUnfinished(const std::string& scene_prefix) = 0;
  // Deletes finished jobs (succeeded, failed, cancelled) last changed before `cutoff_ms` that no
  // unfinished job depends on, with their dependency rows; only `scene`'s when it is not empty.
  // Returns how many.
  virtual absl::StatusOr<int> DeleteFinished(int64_t cutoff_ms, const std::string& scene) = 0;
  virtual absl::StatusOr<QueueStats> Stats(int64_t now_ms) = 0;
};

class QueueStore {
 public:
  virtual ~QueueStore() = default;
  // Runs `body` in one transaction: committed when it returns OK, rolled back otherwise (and on
  // a failed commit, whose error is returned). Read-only bodies may run on a snapshot.
  virtual absl::Status Transact(bool read_only,
                                const std::function<absl::Status(QueueTx&)>& body) = 0;
};

}  // namespace instascene::scheduler
