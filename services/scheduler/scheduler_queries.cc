// The scheduler's read side: a scene's state, the stage registry, jobs by id or page, queue
// statistics, and the live watch of jobs (SchedulerService, scheduler_service.h).
#include <algorithm>
#include <map>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "common/core/status.h"
#include "common/rpc/status.h"
#include "services/scheduler/job_proto.h"
#include "services/scheduler/scheduler_service.h"

namespace instascene::scheduler {

using auth::Role;
using rpc::ToGrpcStatus;

grpc::Status SchedulerService::GetScene(grpc::ServerContext* context,
                                        const v1::GetSceneRequest* request, v1::Scene* response) {
  absl::StatusOr<auth::Identity> who =
      Caller(context, {Role::kClient, Role::kWorker, Role::kAdmin});
  if (!who.ok()) return ToGrpcStatus(who.status());
  if (request->scene().empty())
    return ToGrpcStatus(absl::InvalidArgumentError("GetScene: no scene given"));
  absl::StatusOr<SceneSummary> scene = queue_->GetScene(auth::StoredScene(*who, request->scene()));
  if (!scene.ok()) return ToGrpcStatus(scene.status());
  response->set_name(auth::ShownScene(*who, scene->scene));
  rpc::ToProto(scene->scene_manifest, response->mutable_scene_manifest());
  for (const StageOutput& o : scene->outputs) {
    v1::StageOutput* out = response->add_outputs();
    out->set_kind(o.kind);
    out->set_item(o.item);
    out->set_job_id(o.job_id);
    rpc::ToProto(o.output, out->mutable_output_manifest());
    rpc::ToProto(o.scene_manifest, out->mutable_scene_manifest());
    out->set_completed_unix_ms(o.completed_ms);
  }
  for (const auto& [state, n] : scene->jobs_by_state)
    (*response->mutable_jobs_by_state())[state] = n;
  return grpc::Status::OK;
}

grpc::Status SchedulerService::ListStages(grpc::ServerContext* context,
                                          const v1::ListStagesRequest*,
                                          v1::ListStagesResponse* response) {
  if (auto who = Caller(context, {Role::kClient, Role::kWorker, Role::kAdmin}); !who.ok())
    return ToGrpcStatus(who.status());
  static constexpr const char* kTypes[] = {"bool", "int", "double", "string"};
  for (const std::string& kind : stages_->Kinds()) {
    const pipeline::StageSpec& spec = stages_->Find(kind)->spec;
    v1::StageInfo* info = response->add_stages();
    info->set_kind(spec.kind);
    info->set_description(spec.description);
    info->set_fans_out(spec.fans_out);
    for (const pipeline::PlannedInput& in : spec.inputs) {
      v1::StageInput* i = info->add_inputs();
      i->set_stage(in.stage);
      i->set_mode(pipeline::InputModeName(in.mode));
    }
    for (const pipeline::ParamSpec& p : spec.parameters) {
      v1::StageParameter* out = info->add_parameters();
      out->set_name(p.name);
      out->set_type(kTypes[static_cast<int>(p.type)]);
      out->set_default_json(p.default_value.dump());
      out->set_min(p.min);
      out->set_max(p.max);
      for (const std::string& c : p.choices) out->add_choices(c);
      out->set_help(p.help);
    }
  }
  return grpc::Status::OK;
}

grpc::Status SchedulerService::GetJob(grpc::ServerContext* context,
                                      const v1::GetJobRequest* request, v1::Job* response) {
  absl::StatusOr<auth::Identity> who =
      Caller(context, {Role::kClient, Role::kWorker, Role::kAdmin});
  if (!who.ok()) return ToGrpcStatus(who.status());
  absl::StatusOr<Job> job = VisibleJob(*who, request->job_id());
  if (!job.ok()) return ToGrpcStatus(job.status());
  ToCallerProto(*who, *job, response);
  return grpc::Status::OK;
}

grpc::Status SchedulerService::ListJobs(grpc::ServerContext* context,
                                        const v1::ListJobsRequest* request,
                                        v1::ListJobsResponse* response) {
  absl::StatusOr<auth::Identity> who = Caller(context, {Role::kClient, Role::kAdmin});
  if (!who.ok()) return ToGrpcStatus(who.status());
  JobFilter filter;
  filter.scene = auth::StoredScene(*who, request->scene());
  if (who->scoped()) filter.scene_prefix = who->tenant + ":";
  if (request->state() != v1::JOB_STATE_UNSPECIFIED) {
    if (request->state() < v1::JOB_STATE_QUEUED || request->state() > v1::JOB_STATE_CANCELLED)
      return ToGrpcStatus(absl::InvalidArgumentError("unknown job state"));
    filter.state = static_cast<JobState>(static_cast<int>(request->state()));
  }
  filter.limit = request->limit() > 0 ? std::min(request->limit(), 1000) : 100;
  if (!request->page_token().empty()) {
    if (!absl::SimpleAtoi(request->page_token(), &filter.before_seq) || filter.before_seq <= 0)
      return ToGrpcStatus(absl::InvalidArgumentError("ListJobs: malformed page_token"));
  }
  absl::StatusOr<std::vector<Job>> jobs = queue_->List(filter);
  if (!jobs.ok()) return ToGrpcStatus(jobs.status());
  for (const Job& j : *jobs) ToCallerProto(*who, j, response->add_jobs());
  if (static_cast<int>(jobs->size()) == filter.limit && !jobs->empty())
    response->set_next_page_token(std::to_string(jobs->back().seq));
  return grpc::Status::OK;
}

grpc::Status SchedulerService::GetQueueStats(grpc::ServerContext* context,
                                             const v1::GetQueueStatsRequest*,
                                             v1::QueueStats* response) {
  if (auto who = Caller(context, {Role::kAdmin}); !who.ok()) return ToGrpcStatus(who.status());
  absl::StatusOr<QueueStats> stats = queue_->Stats();
  if (!stats.ok()) return ToGrpcStatus(stats.status());
  for (const auto& [state, n] : stats->jobs_by_state)
    (*response->mutable_jobs_by_state())[state] = n;
  response->set_scenes(stats->scenes);
  response->set_oldest_queued_age_ms(stats->oldest_queued_age_ms);
  std::map<std::string, v1::StageQueueStats> stages;
  for (const QueueStats::StageState& s : stats->jobs_by_stage) {
    stages[s.stage].set_stage(s.stage);
    (*stages[s.stage].mutable_jobs_by_state())[s.state] = s.jobs;
  }
  for (const auto& [stage, age] : stats->oldest_queued_age_ms_by_stage) {
    stages[stage].set_stage(stage);
    stages[stage].set_oldest_queued_age_ms(age);
  }
  for (auto& [stage, s] : stages) *response->add_stages() = std::move(s);
  return grpc::Status::OK;
}

grpc::Status SchedulerService::WatchJobs(grpc::ServerContext* context,
                                         const v1::WatchJobsRequest* request,
                                         grpc::ServerWriter<v1::Job>* writer) {
  absl::StatusOr<auth::Identity> who = Caller(context, {Role::kClient, Role::kAdmin});
  if (!who.ok()) return ToGrpcStatus(who.status());
  JobFilter filter;
  filter.ids.assign(request->job_ids().begin(), request->job_ids().end());
  if (filter.ids.size() > 1000)
    return ToGrpcStatus(absl::InvalidArgumentError("WatchJobs: at most 1000 job_ids"));
  for (const std::string& id : filter.ids) {
    if (auto visible = VisibleJob(*who, id); !visible.ok()) return ToGrpcStatus(visible.status());
  }
  filter.scene = auth::StoredScene(*who, request->scene());
  filter.limit = 1000;
  if (filter.ids.empty() && filter.scene.empty())
    return ToGrpcStatus(absl::InvalidArgumentError("WatchJobs: give job_ids or a scene"));
  std::map<std::string, std::string> sent;  // id -> fingerprint of the last snapshot sent
  while (!context->IsCancelled()) {
    uint64_t seen;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (stopping_) return grpc::Status(grpc::StatusCode::UNAVAILABLE, "scheduler shutting down");
      seen = version_;
    }
    absl::StatusOr<std::vector<Job>> jobs = queue_->List(filter);
    if (!jobs.ok()) return ToGrpcStatus(jobs.status());
    if (jobs->empty())
      return ToGrpcStatus(absl::NotFoundError("no jobs for scene " + request->scene()));
    bool all_final = true;
    for (auto it = jobs->rbegin(); it != jobs->rend(); ++it) {  // oldest first
      const Job& job = *it;
      all_final &= IsFinal(job.state);
      const std::string fingerprint =
          absl::StrCat(job.state, "/", job.updated_ms, "/", job.progress.step, "/", job.attempts);
      if (sent[job.id] == fingerprint) continue;
      sent[job.id] = fingerprint;
      v1::Job out;
      ToCallerProto(*who, job, &out);
      if (!writer->Write(out)) return grpc::Status::CANCELLED;
    }
    if (all_final) return grpc::Status::OK;
    std::unique_lock<std::mutex> lock(mutex_);
    changed_.wait_for(lock, std::chrono::milliseconds(500),
                      [&] { return version_ != seen || stopping_; });
  }
  return grpc::Status::CANCELLED;
}

}  // namespace instascene::scheduler
