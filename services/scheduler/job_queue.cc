#include "services/scheduler/job_queue.h"

#include <algorithm>
#include <cmath>

#include "absl/strings/str_cat.h"
#include "common/core/status.h"

namespace instascene::scheduler {

absl::Status QueueOptions::Validate() const {
  if (min_lease_ms <= 0 || lease_ms < min_lease_ms || max_lease_ms < lease_ms)
    return absl::InvalidArgumentError("leases: need 0 < min_lease_ms <= lease_ms <= max_lease_ms");
  if (backoff_base_ms < 0 || backoff_cap_ms < backoff_base_ms)
    return absl::InvalidArgumentError("backoff: need 0 <= base <= cap");
  if (backoff_jitter < 0 || backoff_jitter >= 1)
    return absl::InvalidArgumentError("backoff_jitter must be in [0, 1)");
  if (max_items < 0) return absl::InvalidArgumentError("max_items must be >= 0");
  if (max_unfinished_per_tenant < 0)
    return absl::InvalidArgumentError("max_unfinished_per_tenant must be >= 0");
  return absl::OkStatus();
}

JobQueue::JobQueue(std::unique_ptr<QueueStore> store, const QueueOptions& options, Clock* clock)
    : store_(std::move(store)), options_(options), clock_(clock), rng_(options.seed) {}

absl::Status JobQueue::Apply(Job* job, JobEvent event) {
  absl::StatusOr<JobState> next = Transition(job->state, event);
  if (!next.ok()) return Annotate(next.status(), absl::StrCat("job ", job->id));
  job->state = *next;
  job->updated_ms = clock_->NowMs();
  return absl::OkStatus();
}

absl::StatusOr<Job> JobQueue::Load(QueueTx& tx, const std::string& id) {
  ASSIGN_OR_RETURN(std::optional<Job> job, tx.Get(id));
  if (!job) return absl::NotFoundError(absl::StrCat("job ", id, " not found"));
  return *std::move(job);
}

absl::StatusOr<Job> JobQueue::LoadHeld(QueueTx& tx, const std::string& id,
                                       const std::string& token) {
  ASSIGN_OR_RETURN(Job job, Load(tx, id));
  if (!IsHeld(job.state) || job.lease_token != token)
    return absl::FailedPreconditionError(
        absl::StrCat("job ", id, ": lease lost (job is ", JobStateName(job.state),
                     job.lease_token != token ? ", held under another lease" : "", ")"));
  return job;
}

int64_t JobQueue::BackoffMs(int attempts) {
  const double raw =
      static_cast<double>(options_.backoff_base_ms) * std::pow(2.0, std::max(0, attempts - 1));
  const double capped = std::min(raw, static_cast<double>(options_.backoff_cap_ms));
  std::lock_guard<std::mutex> lock(rng_mutex_);
  const double u = std::uniform_real_distribution<double>(0.0, 1.0)(rng_);
  return static_cast<int64_t>(capped * (1.0 - options_.backoff_jitter * u));
}

std::string JobQueue::NewToken(int attempt) {
  std::lock_guard<std::mutex> lock(rng_mutex_);
  return absl::StrCat(attempt, "-", rng_() & 0xffffffffffffULL);
}

absl::StatusOr<std::optional<Lease>> JobQueue::LeaseNext(const std::vector<std::string>& kinds,
                                                         const std::string& worker_id,
                                                         int64_t lease_ms) {
  if (kinds.empty()) return absl::InvalidArgumentError("lease: no job kinds given");
  if (worker_id.empty()) return absl::InvalidArgumentError("lease: worker_id is empty");
  lease_ms = lease_ms <= 0 ? options_.lease_ms
                           : std::clamp(lease_ms, options_.min_lease_ms, options_.max_lease_ms);
  std::optional<Lease> lease;
  RETURN_IF_ERROR(store_->Transact(false, [&](QueueTx& tx) -> absl::Status {
    lease.reset();
    const int64_t now = clock_->NowMs();
    ASSIGN_OR_RETURN(std::optional<std::string> next, tx.NextReady(kinds, now));
    if (!next) return absl::OkStatus();
    ASSIGN_OR_RETURN(Job job, Load(tx, *next));
    RETURN_IF_ERROR(Apply(&job, JobEvent::kLease));
    ++job.attempts;
    job.worker_id = worker_id;
    job.lease_ms = lease_ms;
    job.lease_expires_ms = now + lease_ms;
    job.lease_token = NewToken(job.attempts);
    job.progress = {};
    RETURN_IF_ERROR(tx.Update(job));
    RETURN_IF_ERROR(tx.TouchScene(job.scene, now));
    Lease l{job, job.lease_token, {}};
    for (const JobDependency& d : job.dependencies) {
      ASSIGN_OR_RETURN(Job dep, Load(tx, d.job_id));
      if (dep.state != JobState::kSucceeded && MayLeaveOut(job, d.name) &&
          (dep.state == JobState::kFailed || dep.state == JobState::kCancelled))
        continue;  // a partial join runs without its failed items
      if (dep.state != JobState::kSucceeded)
        return absl::InternalError(absl::StrCat("job ", job.id, " was ready but its input ", d.name,
                                                " (", d.job_id, ") is ", JobStateName(dep.state)));
      l.inputs.emplace_back(d.name, dep.output_manifest);
    }
    lease = std::move(l);
    return absl::OkStatus();
  }));
  return lease;
}

absl::StatusOr<HeartbeatResult> JobQueue::Heartbeat(const std::string& id, const std::string& token,
                                                    const JobProgress& progress) {
  HeartbeatResult result;
  RETURN_IF_ERROR(store_->Transact(false, [&](QueueTx& tx) -> absl::Status {
    ASSIGN_OR_RETURN(Job job, LoadHeld(tx, id, token));
    RETURN_IF_ERROR(Apply(&job, JobEvent::kProgress));
    job.progress = progress;
    job.lease_expires_ms = clock_->NowMs() + (job.lease_ms > 0 ? job.lease_ms : options_.lease_ms);
    RETURN_IF_ERROR(tx.Update(job));
    result = {job.cancel_requested, job.lease_expires_ms};
    return absl::OkStatus();
  }));
  return result;
}

absl::Status JobQueue::Complete(const std::string& id, const std::string& token,
                                const store::Digest& output, int64_t items) {
  RETURN_IF_ERROR(store::ValidateDigest(output));
  if (items < -1 || items > options_.max_items)
    return absl::InvalidArgumentError(
        absl::StrCat("job ", id, ": ", items, " items is outside [0, ", options_.max_items, "]"));
  return store_->Transact(false, [&](QueueTx& tx) -> absl::Status {
    ASSIGN_OR_RETURN(Job job, LoadHeld(tx, id, token));
    if (!job.plans.empty() && items < 0)
      return absl::InvalidArgumentError(absl::StrCat(
          "job ", id, " (", job.kind, ") fans out: its completion must report its items"));
    RETURN_IF_ERROR(Apply(&job, JobEvent::kSucceed));
    job.output_manifest = output;
    job.items = items;
    job.lease_token.clear();
    job.error.clear();
    RETURN_IF_ERROR(tx.Update(job));
    ASSIGN_OR_RETURN(std::vector<std::string> dependents, tx.Dependents(id));
    for (const std::string& d : dependents) {
      ASSIGN_OR_RETURN(Job dependent, Load(tx, d));
      if (dependent.pending > 0 && dependent.state == JobState::kQueued) {
        --dependent.pending;
        RETURN_IF_ERROR(tx.Update(dependent));
      }
    }
    std::vector<SubmitResult> created;
    for (const nlohmann::json& plan : job.plans) RETURN_IF_ERROR(Expand(tx, job, plan, &created));
    return absl::OkStatus();
  });
}

absl::Status JobQueue::RetryOrFail(QueueTx& tx, Job* job, const std::string& error,
                                   bool retryable) {
  if (job->cancel_requested) return EndCancelled(tx, job, error);
  job->error = error;
  job->lease_token.clear();
  job->lease_expires_ms = 0;
  if (retryable && job->attempts < job->max_attempts) {
    RETURN_IF_ERROR(Apply(job, JobEvent::kRetry));
    job->not_before_ms = clock_->NowMs() + BackoffMs(job->attempts);
    return tx.Update(*job);
  }
  RETURN_IF_ERROR(Apply(job, JobEvent::kGiveUp));
  RETURN_IF_ERROR(tx.Update(*job));
  return CancelDependents(tx, job->id, absl::StrCat("dependency ", job->id, " failed: ", error));
}

absl::Status JobQueue::Fail(const std::string& id, const std::string& token, FailureKind kind,
                            const std::string& error) {
  return store_->Transact(false, [&](QueueTx& tx) -> absl::Status {
    ASSIGN_OR_RETURN(Job job, LoadHeld(tx, id, token));
    switch (kind) {
      case FailureKind::kCancelled:
        if (!job.cancel_requested)
          return absl::FailedPreconditionError(
              absl::StrCat("job ", id, ": reported cancelled but no cancellation was requested"));
        return EndCancelled(tx, &job, error.empty() ? "cancelled by request" : error);
      case FailureKind::kReleased:
        if (job.cancel_requested) return EndCancelled(tx, &job, error);
        RETURN_IF_ERROR(Apply(&job, JobEvent::kRetry));
        job.attempts = std::max(0, job.attempts - 1);
        job.error = error;
        job.lease_token.clear();
        job.lease_expires_ms = 0;
        job.not_before_ms = 0;
        return tx.Update(job);
      case FailureKind::kRetryable:
      case FailureKind::kPermanent:
        return RetryOrFail(tx, &job, error, kind == FailureKind::kRetryable);
    }
    return absl::InvalidArgumentError("unknown failure kind");
  });
}

absl::StatusOr<int> JobQueue::PruneFinished(int64_t retention_ms) {
  if (retention_ms < 0) return absl::InvalidArgumentError("retention must be >= 0");
  int pruned = 0;
  RETURN_IF_ERROR(store_->Transact(false, [&](QueueTx& tx) -> absl::Status {
    ASSIGN_OR_RETURN(pruned, tx.DeleteFinished(clock_->NowMs() - retention_ms, ""));
    return absl::OkStatus();
  }));
  return pruned;
}

absl::StatusOr<int> JobQueue::RescueExpired() {
  int handled = 0;
  RETURN_IF_ERROR(store_->Transact(false, [&](QueueTx& tx) -> absl::Status {
    const int64_t now = clock_->NowMs();
    ASSIGN_OR_RETURN(std::vector<std::string> expired, tx.Expired(now));
    handled = 0;
    for (const std::string& id : expired) {
      ASSIGN_OR_RETURN(Job job, Load(tx, id));
      // Another scheduler replica may have completed, rescued or renewed it meanwhile.
      if (!IsHeld(job.state) || job.lease_expires_ms >= now) continue;
      ++handled;
      RETURN_IF_ERROR(
          RetryOrFail(tx, &job,
                      absl::StrCat("lease of worker '", job.worker_id, "' expired (attempt ",
                                   job.attempts, " of ", job.max_attempts, ")"),
                      /*retryable=*/true));
    }
    return absl::OkStatus();
  }));
  return handled;
}

}  // namespace instascene::scheduler
