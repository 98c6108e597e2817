#include "services/scheduler/scheduler_service.h"

#include <algorithm>

#include <spdlog/spdlog.h>
#include "absl/strings/str_cat.h"

#include "common/core/status.h"
#include "common/core/timer.h"
#include "common/rpc/status.h"
#include "common/store/manifest.h"
#include "services/scheduler/job_proto.h"
#include "services/scheduler/scheduler_metrics.h"

namespace instascene::scheduler {

using auth::Role;
using rpc::ToGrpcStatus;

void SchedulerService::ToCallerProto(const auth::Identity& who, const Job& job, v1::Job* out) {
  ToProto(job, out);
  out->set_scene(auth::ShownScene(who, job.scene));
}

absl::StatusOr<auth::Identity> SchedulerService::Caller(grpc::ServerContext* context,
                                                        std::initializer_list<Role> roles) const {
  return auth::Authorize(options_.auth, context, roles);
}

absl::StatusOr<Job> SchedulerService::VisibleJob(const auth::Identity& who, const std::string& id) {
  ASSIGN_OR_RETURN(Job job, queue_->Get(id));
  if (!auth::MaySee(who, job.scene))
    return absl::NotFoundError(absl::StrCat("job ", id.substr(0, 80), " not found"));
  return job;
}

absl::Status SchedulerService::GrantOutputs(const Job& job, const store::Digest& output) {
  const std::string tenant = auth::SceneTenant(job.scene);
  if (tenant.empty()) return absl::OkStatus();
  ASSIGN_OR_RETURN(std::string bytes, store_->Read(output));
  ASSIGN_OR_RETURN(store::Manifest manifest, store::ParseManifest(bytes, "output manifest"));
  std::vector<store::Digest> digests = manifest.Digests();
  digests.push_back(output);
  return store_->Grant(tenant, digests);
}

SchedulerService::SchedulerService(JobQueue* queue, store::BlobStore* store,
                                   const pipeline::StageRegistry* stages,
                                   const SchedulerServiceOptions& options)
    : queue_(queue), store_(store), stages_(stages), options_(options) {
  rescuer_ = std::thread([this] { RescueLoop(); });
}

SchedulerService::~SchedulerService() { Stop(); }

void SchedulerService::Stop() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stopping_ = true;
  }
  changed_.notify_all();
  if (rescuer_.joinable()) rescuer_.join();
}

void SchedulerService::Notify() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    ++version_;
  }
  changed_.notify_all();
}

void SchedulerService::RescueLoop() {
  Stopwatch prune_watch;
  std::unique_lock<std::mutex> lock(mutex_);
  while (!stopping_) {
    changed_.wait_for(lock, std::chrono::milliseconds(options_.rescue_interval_ms));
    if (stopping_) break;
    lock.unlock();
    absl::StatusOr<int> rescued = queue_->RescueExpired();
    if (rescued.ok()) RecordRescued(*rescued);
    if (options_.retention_ms > 0 &&
        prune_watch.ElapsedSeconds() * 1000 >= options_.prune_interval_ms) {
      prune_watch = Stopwatch();
      absl::StatusOr<int> pruned = queue_->PruneFinished(options_.retention_ms);
      if (pruned.ok() && *pruned > 0)
        spdlog::info("scheduler: pruned {} jobs finished over {} s ago", *pruned,
                     options_.retention_ms / 1000);
      else if (!pruned.ok())
        spdlog::warn("scheduler: pruning failed: {}", pruned.status().ToString());
    }
    lock.lock();
    if (rescued.ok() && *rescued > 0) {
      ++version_;
      changed_.notify_all();
    }
  }
}

absl::Status SchedulerService::Submit(const auth::Identity& who,
                                      const v1::SubmitPipelineRequest& request,
                                      v1::SubmitPipelineResponse* response) {
  ASSIGN_OR_RETURN(store::Digest manifest_digest,
                   rpc::ParseProtoDigest(request.scene_manifest(), "scene_manifest"));
  if (who.scoped()) {  // a tenant submits only a scene whose manifest it holds (else: as absent)
    ASSIGN_OR_RETURN(std::vector<store::Digest> ungranted,
                     store_->FindUngranted(who.tenant, {manifest_digest}));
    if (!ungranted.empty())
      return absl::NotFoundError(
          absl::StrCat("scene manifest ", manifest_digest.ToString(), " is not in the store"));
  }
  ASSIGN_OR_RETURN(store::Manifest manifest, store::ReadManifest(*store_, manifest_digest));
  RETURN_IF_ERROR(store::ValidateSceneManifest(*store_, manifest));
  if (who.scoped()) {  // ... and every file it names
    ASSIGN_OR_RETURN(std::vector<store::Digest> ungranted,
                     store_->FindUngranted(who.tenant, manifest.Digests()));
    if (!ungranted.empty())
      return absl::FailedPreconditionError(
          absl::StrCat("scene manifest refers to ", ungranted.size(),
                       " blobs the store lacks (first: ", ungranted[0].ToString(), ")"));
  }
  nlohmann::json parameters = nlohmann::json::object();
  if (!request.parameters_json().empty()) {
    parameters = nlohmann::json::parse(request.parameters_json(), nullptr, false);
    if (parameters.is_discarded())
      return absl::InvalidArgumentError("parameters_json is not valid JSON");
  }
  if (request.scene().size() > 256 ||
      std::any_of(request.scene().begin(), request.scene().end(),
                  [](char c) { return static_cast<unsigned char>(c) < 0x20 || c == 0x7f; }))
    return absl::InvalidArgumentError("scene name: at most 256 bytes, no control characters");
  SubmitRequest submit;
  submit.scene_manifest = manifest_digest;
  submit.scene = auth::StoredScene(
      who, request.scene().empty() ? manifest_digest.hash.substr(0, 12) : request.scene());
  submit.priority = request.priority();
  submit.max_attempts = options_.max_attempts;
  ASSIGN_OR_RETURN(submit.stages,
                   stages_->Plan({request.stages().begin(), request.stages().end()}, parameters));
  ASSIGN_OR_RETURN(std::vector<SubmitResult> jobs, queue_->Submit(submit));
  for (const SubmitResult& r : jobs) {
    ToCallerProto(who, r.job, response->add_jobs());
    response->add_created(r.created);
  }
  return absl::OkStatus();
}

grpc::Status SchedulerService::SubmitPipeline(grpc::ServerContext* context,
                                              const v1::SubmitPipelineRequest* request,
                                              v1::SubmitPipelineResponse* response) {
  absl::StatusOr<auth::Identity> who = Caller(context, {Role::kClient, Role::kAdmin});
  if (!who.ok()) return ToGrpcStatus(who.status());
  const absl::Status s = Submit(*who, *request, response);
  if (s.ok()) Notify();
  return ToGrpcStatus(s);
}

absl::Status SchedulerService::Lease(const v1::LeaseJobRequest& request,
                                     v1::LeaseJobResponse* response) {
  if (request.worker_id().empty()) return absl::InvalidArgumentError("worker_id is empty");
  const std::vector<std::string> kinds(request.kinds().begin(), request.kinds().end());
  ASSIGN_OR_RETURN(
      std::optional<scheduler::Lease> lease,
      queue_->LeaseNext(kinds, request.worker_id(), int64_t{request.lease_seconds()} * 1000));
  if (!lease) return absl::OkStatus();
  const int64_t ready_ms = std::max(lease->job.created_ms, lease->job.not_before_ms);
  RecordLease(lease->job.kind, std::max<int64_t>(0, lease->job.updated_ms - ready_ms) / 1000.0);
  ToProto(lease->job, response->mutable_job());
  response->set_lease_token(lease->token);
  for (const auto& [name, digest] : lease->inputs)
    (*response->mutable_inputs())[name] = rpc::ToProto(digest);
  return absl::OkStatus();
}

grpc::Status SchedulerService::LeaseJob(grpc::ServerContext* context,
                                        const v1::LeaseJobRequest* request,
                                        v1::LeaseJobResponse* response) {
  if (auto who = Caller(context, {Role::kWorker, Role::kAdmin}); !who.ok())
    return ToGrpcStatus(who.status());
  const absl::Status s = Lease(*request, response);
  if (s.ok() && response->has_job()) Notify();
  return ToGrpcStatus(s);
}

grpc::Status SchedulerService::Heartbeat(grpc::ServerContext* context,
                                         const v1::HeartbeatRequest* request,
                                         v1::HeartbeatResponse* response) {
  if (auto who = Caller(context, {Role::kWorker, Role::kAdmin}); !who.ok())
    return ToGrpcStatus(who.status());
  absl::StatusOr<HeartbeatResult> r =
      queue_->Heartbeat(request->job_id(), request->lease_token(), FromProto(request->progress()));
  if (!r.ok()) return ToGrpcStatus(r.status());
  response->set_cancel_requested(r->cancel_requested);
  response->set_lease_expires_unix_ms(r->lease_expires_ms);
  Notify();
  return grpc::Status::OK;
}

absl::Status SchedulerService::CheckOutput(const std::string& job_id,
                                           const std::string& lease_token,
                                           const store::Digest& output) {
  constexpr int64_t kMaxManifestBytes = int64_t{16} << 20;
  ASSIGN_OR_RETURN(Job job, queue_->Get(job_id));
  // Only the holder of the current lease learns anything about its output's validity.
  if (job.state != JobState::kLeased && job.state != JobState::kRunning)
    return absl::FailedPreconditionError(absl::StrCat("job ", job_id, " is not leased"));
  if (lease_token.empty() || lease_token != job.lease_token)
    return absl::FailedPreconditionError(
        absl::StrCat("job ", job_id, ": the lease token is not the current lease's"));
  ASSIGN_OR_RETURN(std::vector<store::Digest> missing, store_->FindMissing({output}));
  if (!missing.empty())
    return absl::FailedPreconditionError(
        absl::StrCat("output manifest ", output.ToString(), " is not in the store"));
  if (output.size_bytes > kMaxManifestBytes)
    return absl::InvalidArgumentError(absl::StrCat("output manifest of ", output.size_bytes,
                                                   " bytes (at most ", kMaxManifestBytes, ")"));
  ASSIGN_OR_RETURN(std::string bytes, store_->Read(output));
  ASSIGN_OR_RETURN(store::Manifest manifest, store::ParseManifest(bytes, "output manifest"));
  if (manifest.kind != job.kind)
    return absl::InvalidArgumentError(
        absl::StrCat("output manifest of kind \"", manifest.kind, "\" for a ", job.kind, " job"));
  ASSIGN_OR_RETURN(missing, store_->FindMissing(manifest.Digests()));
  if (!missing.empty())
    return absl::FailedPreconditionError(
        absl::StrCat("output manifest refers to ", missing.size(),
                     " blobs the store lacks (first: ", missing[0].ToString(), ")"));
  if (const pipeline::StageDefinition* stage = stages_ ? stages_->Find(job.kind) : nullptr) {
    for (const std::string& file : stage->spec.required_outputs) {
      if (!manifest.files.count(file))
        return absl::InvalidArgumentError(
            absl::StrCat("output of a ", job.kind, " job lacks ", file));
    }
  }
  return absl::OkStatus();
}

grpc::Status SchedulerService::CompleteJob(grpc::ServerContext* context,
                                           const v1::CompleteJobRequest* request,
                                           v1::CompleteJobResponse*) {
  if (auto who = Caller(context, {Role::kWorker, Role::kAdmin}); !who.ok())
    return ToGrpcStatus(who.status());
  absl::StatusOr<store::Digest> output =
      rpc::ParseProtoDigest(request->output_manifest(), "output_manifest");
  if (!output.ok()) return ToGrpcStatus(output.status());
  if (absl::Status bad = CheckOutput(request->job_id(), request->lease_token(), *output); !bad.ok())
    return ToGrpcStatus(bad);
  // Granted before the job shows as succeeded: its tenant can read what it sees finished.
  if (absl::StatusOr<Job> job = queue_->Get(request->job_id()); !job.ok()) {
    return ToGrpcStatus(job.status());
  } else if (absl::Status granted = GrantOutputs(*job, *output); !granted.ok()) {
    return ToGrpcStatus(granted);
  }
  const absl::Status s =
      queue_->Complete(request->job_id(), request->lease_token(), *output, request->items());
  if (s.ok()) {
    if (absl::StatusOr<Job> job = queue_->Get(request->job_id()); job.ok())
      RecordFinished(job->kind, "succeeded");
    Notify();
  }
  return ToGrpcStatus(s);
}

grpc::Status SchedulerService::FailJob(grpc::ServerContext* context,
                                       const v1::FailJobRequest* request, v1::FailJobResponse*) {
  if (auto who = Caller(context, {Role::kWorker, Role::kAdmin}); !who.ok())
    return ToGrpcStatus(who.status());
  absl::StatusOr<FailureKind> kind = FromProto(request->kind());
  if (!kind.ok()) return ToGrpcStatus(kind.status());
  // A worker's error reaches clients (GetJob): no server paths, and bounded.
  const absl::Status s = queue_->Fail(request->job_id(), request->lease_token(), *kind,
                                      rpc::ScrubPaths(request->error().substr(0, 4096)));
  if (s.ok()) {
    if (absl::StatusOr<Job> job = queue_->Get(request->job_id()); job.ok()) {
      RecordFinished(job->kind, job->state == JobState::kQueued      ? "retried"
                                : job->state == JobState::kCancelled ? "cancelled"
                                                                     : "failed");
    }
    Notify();
  }
  return ToGrpcStatus(s);
}

grpc::Status SchedulerService::CancelJob(grpc::ServerContext* context,
                                         const v1::CancelJobRequest* request, v1::Job* response) {
  absl::StatusOr<auth::Identity> who = Caller(context, {Role::kClient, Role::kAdmin});
  if (!who.ok()) return ToGrpcStatus(who.status());
  if (auto visible = VisibleJob(*who, request->job_id()); !visible.ok())
    return ToGrpcStatus(visible.status());
  absl::StatusOr<Job> job = queue_->Cancel(request->job_id());
  if (!job.ok()) return ToGrpcStatus(job.status());
  ToCallerProto(*who, *job, response);
  Notify();
  return grpc::Status::OK;
}

grpc::Status SchedulerService::CancelScene(grpc::ServerContext* context,
                                           const v1::CancelSceneRequest* request,
                                           v1::CancelSceneResponse* response) {
  absl::StatusOr<auth::Identity> who = Caller(context, {Role::kClient, Role::kAdmin});
  if (!who.ok()) return ToGrpcStatus(who.status());
  if (request->scene().empty())
    return ToGrpcStatus(absl::InvalidArgumentError("CancelScene: no scene given"));
  absl::StatusOr<std::vector<Job>> jobs =
      queue_->CancelScene(auth::StoredScene(*who, request->scene()));
  if (!jobs.ok()) return ToGrpcStatus(jobs.status());
  for (const Job& j : *jobs) ToCallerProto(*who, j, response->add_jobs());
  Notify();
  return grpc::Status::OK;
}

grpc::Status SchedulerService::DeleteScene(grpc::ServerContext* context,
                                           const v1::DeleteSceneRequest* request,
                                           v1::DeleteSceneResponse* response) {
  absl::StatusOr<auth::Identity> who = Caller(context, {Role::kClient, Role::kAdmin});
  if (!who.ok()) return ToGrpcStatus(who.status());
  if (request->scene().empty())
    return ToGrpcStatus(absl::InvalidArgumentError("DeleteScene: no scene given"));
  absl::StatusOr<JobQueue::DeletedScene> deleted =
      queue_->DeleteScene(auth::StoredScene(*who, request->scene()));
  if (!deleted.ok()) return ToGrpcStatus(deleted.status());
  response->set_deleted_jobs(deleted->deleted);
  response->set_kept_jobs(deleted->kept);
  Notify();
  return grpc::Status::OK;
}

}  // namespace instascene::scheduler
