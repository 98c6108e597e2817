// JobQueue: reading jobs, scenes and counts.
#include "services/scheduler/job_queue.h"

#include <map>
#include <set>

#include "absl/strings/str_cat.h"
#include "common/core/status.h"

namespace instascene::scheduler {

absl::StatusOr<Job> JobQueue::Get(const std::string& id) {
  Job job;
  RETURN_IF_ERROR(store_->Transact(true, [&](QueueTx& tx) -> absl::Status {
    ASSIGN_OR_RETURN(job, Load(tx, id));
    return absl::OkStatus();
  }));
  return job;
}

absl::StatusOr<std::vector<Job>> JobQueue::List(const JobFilter& filter) {
  std::vector<Job> jobs;
  RETURN_IF_ERROR(store_->Transact(true, [&](QueueTx& tx) -> absl::Status {
    ASSIGN_OR_RETURN(jobs, tx.List(filter));
    return absl::OkStatus();
  }));
  return jobs;
}

absl::StatusOr<QueueStats> JobQueue::Stats() {
  QueueStats stats;
  RETURN_IF_ERROR(store_->Transact(true, [&](QueueTx& tx) -> absl::Status {
    ASSIGN_OR_RETURN(stats, tx.Stats(clock_->NowMs()));
    return absl::OkStatus();
  }));
  return stats;
}

absl::StatusOr<SceneSummary> JobQueue::GetScene(const std::string& scene) {
  if (scene.empty()) return absl::InvalidArgumentError("scene name is empty");
  JobFilter filter;
  filter.scene = scene;
  filter.limit = kMaxSceneJobs;
  ASSIGN_OR_RETURN(std::vector<Job> jobs, List(filter));  // newest first
  if (jobs.empty()) return absl::NotFoundError(absl::StrCat("no jobs for scene ", scene));
  SceneSummary summary;
  summary.scene = scene;
  summary.scene_manifest = jobs.front().scene_manifest;
  std::map<std::string, int64_t> by_state;
  std::map<std::string, const Job*> latest;  // kind -> latest succeeded job that is not per item
  std::map<std::string, std::string> kind_of;
  for (const Job& j : jobs) {
    ++by_state[JobStateName(j.state)];
    kind_of[j.id] = j.kind;
    if (j.state != JobState::kSucceeded || j.item >= 0) continue;
    const Job*& best = latest[j.kind];
    if (best == nullptr || j.updated_ms > best->updated_ms) best = &j;
  }
  std::map<std::pair<std::string, int64_t>, const Job*> chosen;
  for (const auto& [kind, job] : latest) chosen[{kind, -1}] = job;
  for (const Job& j : jobs) {  // per-item outputs of the chosen run of their fan-out source
    if (j.state != JobState::kSucceeded || j.item < 0) continue;
    auto parent_kind = kind_of.find(j.parent);
    if (parent_kind == kind_of.end()) continue;
    auto source = latest.find(parent_kind->second);
    if (source == latest.end() || source->second->id != j.parent) continue;
    const Job*& best = chosen[{j.kind, j.item}];
    if (best == nullptr || j.updated_ms > best->updated_ms) best = &j;
  }
  for (const auto& [key, job] : chosen) {
    summary.outputs.push_back({job->kind, job->item, job->id, job->output_manifest,
                               job->scene_manifest, job->updated_ms});
  }
  for (const auto& [state, n] : by_state) summary.jobs_by_state.emplace_back(state, n);
  return summary;
}

}  // namespace instascene::scheduler
