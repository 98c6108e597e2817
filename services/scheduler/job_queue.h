// services/scheduler/job_queue.h: the durable job queue behind the scheduler. One interface, one
// conformance suite (queue_conformance.h) that every backend passes: SQLite (embedded default,
// sqlite_job_queue.h) now, PostgreSQL for scale-out later. Time comes from an injected clock.
//
// Semantics (docs/SERVICES.md): idempotent submission by key; leasing picks the highest priority
// ready job, then the scene with the fewest held jobs, then the scene served least recently, then
// submission order; a job is ready when queued, past its backoff time and its dependency
// succeeded; leases expire unless heartbeats extend them; lease tokens fence stale workers; a
// failed or cancelled job cancels the jobs that depend on it. Implementations are thread-safe.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "services/scheduler/job.h"

namespace instascene::scheduler {

// Milliseconds since the Unix epoch; tests inject a fake.
class Clock {
 public:
  virtual ~Clock() = default;
  virtual int64_t NowMs() = 0;
};
Clock* RealClock();

struct QueueOptions {
  int64_t lease_ms = 30000;        // lease length; heartbeats extend it by this much
  int64_t backoff_base_ms = 1000;  // first retry delay
  int64_t backoff_cap_ms = 60000;  // delays double per attempt up to this cap
  double backoff_jitter = 0.25;    // delay *= 1 - jitter * U[0,1) (spreads retry storms)
  uint64_t seed = 1;               // jitter random seed

  absl::Status Validate() const;
};

struct SubmitResult {
  Job job;
  bool created = false;  // false: an existing job (maybe already succeeded) was returned
};

struct Lease {
  Job job;
  std::string token;
};

struct HeartbeatResult {
  bool cancel_requested = false;
  int64_t lease_expires_ms = 0;
};

struct JobFilter {
  std::string scene;              // "" = all
  std::optional<JobState> state;  // unset = all
  std::vector<std::string> ids;   // non-empty: exactly these
  int limit = 100;
};

struct QueueStats {
  std::vector<std::pair<std::string, int64_t>> jobs_by_state;
  int64_t scenes = 0;
  int64_t oldest_queued_age_ms = 0;
};

class JobQueue {
 public:
  virtual ~JobQueue() = default;

  virtual absl::StatusOr<SubmitResult> Submit(const JobSpec& spec) = 0;
  // The next ready job of one of `kinds`, or nullopt.
  virtual absl::StatusOr<std::optional<Lease>> LeaseNext(const std::vector<std::string>& kinds,
                                                         const std::string& worker_id,
                                                         int64_t lease_ms = 0) = 0;
  virtual absl::StatusOr<HeartbeatResult> Heartbeat(const std::string& id, const std::string& token,
                                                    const JobProgress& progress) = 0;
  virtual absl::Status Complete(const std::string& id, const std::string& token,
                                const store::Digest& output) = 0;
  // retryable: back to the queue with backoff while attempts are left; cancelled: the worker
  // stopped on a cancellation request.
  virtual absl::Status Fail(const std::string& id, const std::string& token,
                            const std::string& error, bool retryable, bool cancelled) = 0;
  // The worker gives a held job back unfinished (graceful shutdown): queued again at once, and
  // the attempt does not count.
  virtual absl::Status Release(const std::string& id, const std::string& token,
                               const std::string& reason) = 0;
  virtual absl::StatusOr<Job> Cancel(const std::string& id) = 0;
  virtual absl::StatusOr<Job> Get(const std::string& id) = 0;
  virtual absl::StatusOr<std::vector<Job>> List(const JobFilter& filter) = 0;
  virtual absl::StatusOr<QueueStats> Stats() = 0;
  // Returns expired leases to the queue (or fails / cancels them); the number handled.
  virtual absl::StatusOr<int> RescueExpired() = 0;
};

}  // namespace instascene::scheduler
