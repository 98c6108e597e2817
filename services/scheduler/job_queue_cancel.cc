// JobQueue: cancelling jobs and what depends on them, and deleting a scene whose jobs ended.
#include "services/scheduler/job_queue.h"

#include <algorithm>
#include <limits>
#include <map>
#include <set>

#include "absl/strings/str_cat.h"
#include "common/core/status.h"

namespace instascene::scheduler {

bool JobQueue::MayLeaveOut(const Job& job, const std::string& name) const {
  return options_.partial_join_kinds.count(job.kind) > 0 && name.find('/') != std::string::npos;
}

absl::Status JobQueue::CancelDependents(QueueTx& tx, const std::string& id,
                                        const std::string& why) {
  ASSIGN_OR_RETURN(std::vector<std::string> dependents, tx.Dependents(id));
  for (const std::string& d : dependents) {
    ASSIGN_OR_RETURN(Job job, Load(tx, d));
    bool left_out = false;
    for (const JobDependency& dep : job.dependencies)
      left_out |= dep.job_id == id && MayLeaveOut(job, dep.name);
    if (left_out && job.state == JobState::kQueued) {
      if (job.pending > 0) --job.pending;  // runs over the items that succeeded
      RETURN_IF_ERROR(tx.Update(job));
    } else if (job.state == JobState::kQueued) {
      RETURN_IF_ERROR(EndCancelled(tx, &job, why));
    } else if (IsHeld(job.state) && !job.cancel_requested) {
      job.cancel_requested = true;  // cannot happen (held jobs wait for success); kept safe
      RETURN_IF_ERROR(tx.Update(job));
    }
  }
  return absl::OkStatus();
}

absl::Status JobQueue::EndCancelled(QueueTx& tx, Job* job, const std::string& why) {
  RETURN_IF_ERROR(Apply(job, JobEvent::kCancel));
  job->error = why;
  job->lease_token.clear();
  job->lease_expires_ms = 0;
  RETURN_IF_ERROR(tx.Update(*job));
  return CancelDependents(tx, job->id, absl::StrCat("dependency ", job->id, " was cancelled"));
}

absl::StatusOr<Job> JobQueue::Cancel(const std::string& id) {
  Job result;
  RETURN_IF_ERROR(store_->Transact(false, [&](QueueTx& tx) -> absl::Status {
    ASSIGN_OR_RETURN(result, Load(tx, id));
    if (result.state == JobState::kCancelled) return absl::OkStatus();
    if (IsFinal(result.state))
      return absl::FailedPreconditionError(
          absl::StrCat("job ", id, " is already ", JobStateName(result.state)));
    if (result.state == JobState::kQueued) return EndCancelled(tx, &result, "cancelled by request");
    // Held: the worker sees the request in its next heartbeat and acknowledges it.
    result.cancel_requested = true;
    result.updated_ms = clock_->NowMs();
    return tx.Update(result);
  }));
  return result;
}

absl::StatusOr<JobQueue::DeletedScene> JobQueue::DeleteScene(const std::string& scene) {
  if (scene.empty()) return absl::InvalidArgumentError("delete: scene is empty");
  DeletedScene result;
  RETURN_IF_ERROR(store_->Transact(false, [&](QueueTx& tx) -> absl::Status {
    JobFilter filter;
    filter.scene = scene;
    filter.limit = kMaxSceneJobs;
    ASSIGN_OR_RETURN(std::vector<Job> jobs, tx.List(filter));
    if (jobs.empty()) return absl::NotFoundError(absl::StrCat("no jobs for scene ", scene));
    const auto unfinished =
        std::count_if(jobs.begin(), jobs.end(), [](const Job& j) { return !IsFinal(j.state); });
    if (unfinished > 0)
      return absl::FailedPreconditionError(
          absl::StrCat("scene ", scene, " has ", unfinished,
                       " unfinished jobs: cancel the scene and delete it once they have ended"));
    ASSIGN_OR_RETURN(result.deleted, tx.DeleteFinished(std::numeric_limits<int64_t>::max(), scene));
    result.kept = static_cast<int>(jobs.size()) - result.deleted;
    return absl::OkStatus();
  }));
  return result;
}

absl::StatusOr<std::vector<Job>> JobQueue::CancelScene(const std::string& scene) {
  if (scene.empty()) return absl::InvalidArgumentError("cancel: scene is empty");
  std::vector<Job> affected;
  RETURN_IF_ERROR(store_->Transact(false, [&](QueueTx& tx) -> absl::Status {
    affected.clear();
    JobFilter filter;
    filter.scene = scene;
    filter.limit = kMaxSceneJobs;
    ASSIGN_OR_RETURN(std::vector<Job> jobs, tx.List(filter));
    if (jobs.empty()) return absl::NotFoundError(absl::StrCat("no jobs for scene ", scene));
    std::vector<std::string> unfinished;
    for (auto it = jobs.rbegin(); it != jobs.rend(); ++it)  // oldest first: roots cascade
      if (!IsFinal(it->state)) unfinished.push_back(it->id);
    for (const std::string& id : unfinished) {
      ASSIGN_OR_RETURN(Job job, Load(tx, id));  // fresh: an earlier cascade may have ended it
      if (IsFinal(job.state)) continue;
      if (job.state == JobState::kQueued) {
        RETURN_IF_ERROR(EndCancelled(tx, &job, "scene cancelled by request"));
      } else if (!job.cancel_requested) {
        job.cancel_requested = true;
        job.updated_ms = clock_->NowMs();
        RETURN_IF_ERROR(tx.Update(job));
      }
    }
    for (const std::string& id : unfinished) {
      ASSIGN_OR_RETURN(Job job, Load(tx, id));
      affected.push_back(std::move(job));
    }
    return absl::OkStatus();
  }));
  return affected;
}

}  // namespace instascene::scheduler
