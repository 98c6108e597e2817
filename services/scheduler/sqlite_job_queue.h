// services/scheduler/sqlite_job_queue.h: the embedded JobQueue backend: one SQLite file in WAL mode
// with synchronous=FULL, so every acknowledged change survives a crash of the process. Mutations
// run in BEGIN IMMEDIATE transactions; one connection, serialised by a mutex (the scheduler process
// owns the file; other processes talk to the scheduler over gRPC). Thread-safe.
#pragma once

#include <sqlite3.h>

#include <mutex>
#include <random>

#include "services/scheduler/job_queue.h"

namespace instascene::scheduler {

class SqliteJobQueue final : public JobQueue {
 public:
  static absl::StatusOr<std::unique_ptr<SqliteJobQueue>> Open(const std::string& path,
                                                              const QueueOptions& options,
                                                              Clock* clock = RealClock());
  ~SqliteJobQueue() override;

  absl::StatusOr<SubmitResult> Submit(const JobSpec& spec) override;
  absl::StatusOr<std::optional<Lease>> LeaseNext(const std::vector<std::string>& kinds,
                                                 const std::string& worker_id,
                                                 int64_t lease_ms) override;
  absl::StatusOr<HeartbeatResult> Heartbeat(const std::string& id, const std::string& token,
                                            const JobProgress& progress) override;
  absl::Status Complete(const std::string& id, const std::string& token,
                        const store::Digest& output) override;
  absl::Status Fail(const std::string& id, const std::string& token, const std::string& error,
                    bool retryable, bool cancelled) override;
  absl::Status Release(const std::string& id, const std::string& token,
                       const std::string& reason) override;
  absl::StatusOr<Job> Cancel(const std::string& id) override;
  absl::StatusOr<Job> Get(const std::string& id) override;
  absl::StatusOr<std::vector<Job>> List(const JobFilter& filter) override;
  absl::StatusOr<QueueStats> Stats() override;
  absl::StatusOr<int> RescueExpired() override;

 private:
  SqliteJobQueue(sqlite3* db, const QueueOptions& options, Clock* clock);
  absl::Status Exec(const std::string& sql);
  absl::StatusOr<std::optional<Job>> Load(const std::string& id);
  absl::Status Save(const Job& job);  // updates every mutable column of an existing row
  // Applies `event` to a loaded job through Transition and stamps updated_ms.
  absl::Status Apply(Job* job, JobEvent event);
  // Held job whose token matches, else FailedPrecondition ("lease lost").
  absl::StatusOr<Job> LoadHeld(const std::string& id, const std::string& token);
  // Retry with backoff or give up; cancels dependents when the job ends.
  absl::Status RetryOrFail(Job* job, const std::string& error, bool retryable);
  absl::Status CancelDependents(const std::string& id, const std::string& why);
  int64_t BackoffMs(int attempts);
  // Runs `body` inside BEGIN IMMEDIATE ... COMMIT (ROLLBACK on error).
  template <typename Fn>
  auto InTransaction(Fn&& body) -> decltype(body());

  sqlite3* db_;
  QueueOptions options_;
  Clock* clock_;
  std::mutex mutex_;
  std::mt19937_64 rng_;
};

}  // namespace instascene::scheduler
