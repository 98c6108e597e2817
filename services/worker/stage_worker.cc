#include "services/worker/stage_worker.h"

#include <unistd.h>

#include <filesystem>
#include <set>

#include <spdlog/spdlog.h>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "common/core/status.h"
#include "common/core/timer.h"
#include "common/metrics/metrics.h"
#include "common/rpc/status.h"
#include "common/store/manifest.h"
#include "services/worker/input_cache.h"
#include "services/worker/lease_heartbeat.h"

namespace instascene::worker {
namespace fs = std::filesystem;

namespace {

// Worker metrics (issue 16): jobs running in this process and how long each attempt took.
prometheus::Family<prometheus::Gauge>& JobsRunning() {
  static auto& f = prometheus::BuildGauge()
                       .Name("instascene_worker_jobs_running")
                       .Help("Jobs this process is running now (busy workers), by stage")
                       .Register(metrics::Registry());
  return f;
}

prometheus::Family<prometheus::Histogram>& JobDurations() {
  static auto& f = prometheus::BuildHistogram()
                       .Name("instascene_worker_job_duration_seconds")
                       .Help(
                           "Wall time of a job attempt in the worker (inputs, stage, upload), by "
                           "stage and outcome")
                       .Register(metrics::Registry());
  return f;
}

// Bad input or parameters will fail again: permanent. Everything else may be transient.
v1::FailureKind FailureFor(absl::StatusCode code) {
  switch (code) {
    case absl::StatusCode::kInvalidArgument:
    case absl::StatusCode::kFailedPrecondition:
    case absl::StatusCode::kNotFound:
    case absl::StatusCode::kOutOfRange:
    case absl::StatusCode::kUnimplemented:
    case absl::StatusCode::kResourceExhausted:  // too large for this worker: will not fit next time
      return v1::FAILURE_KIND_PERMANENT;
    default:
      return v1::FAILURE_KIND_RETRYABLE;
  }
}

// Why a job did not succeed, as the scheduler and clients read it: cancelled, handed back
// (draining) or failed with its error (paths scrubbed). Returns the outcome's metrics label.
const char* SetFailure(bool cancel_requested, bool handed_back, const absl::Status& status,
                       const std::string& worker_id, v1::FailJobRequest* request) {
  if (cancel_requested) {
    request->set_kind(v1::FAILURE_KIND_CANCELLED);
    request->set_error("cancelled by request");
    return "cancelled";
  }
  if (handed_back) {
    request->set_kind(v1::FAILURE_KIND_RELEASED);
    request->set_error(absl::StrCat("handed back by worker ", worker_id, " (draining)"));
    return "handed_back";
  }
  request->set_kind(FailureFor(status.code()));
  request->set_error(rpc::ScrubPaths(status.ToString()));  // read by clients
  return "failed";
}

}  // namespace

absl::Status WorkerOptions::Validate(const pipeline::StageRegistry& stages) const {
  if (kinds.empty()) return absl::InvalidArgumentError("worker: no job kinds");
  for (const std::string& k : kinds) {
    const pipeline::StageDefinition* stage = stages.Find(k);
    if (stage == nullptr || !stage->run)
      return absl::InvalidArgumentError(
          absl::StrCat("worker: this binary cannot run stage '", k, "' (it runs ",
                       absl::StrJoin(stages.RunnableKinds(), ", "), ")"));
  }
  if (work_dir.empty()) return absl::InvalidArgumentError("worker: work_dir is empty");
  if (poll_interval_ms <= 0 || heartbeat_interval_ms <= 0)
    return absl::InvalidArgumentError("worker: intervals must be > 0");
  if (cache_bytes < 0) return absl::InvalidArgumentError("worker: cache_bytes must be >= 0");
  return absl::OkStatus();
}

StageWorker::StageWorker(WorkerOptions options, store::BlobStore* store,
                         const pipeline::StageRegistry* stages)
    : options_(std::move(options)), store_(store), stages_(stages) {
  if (options_.worker_id.empty()) {
    char host[256] = "host";
    gethostname(host, sizeof(host) - 1);
    options_.worker_id =
        absl::StrCat(host, "-", ::getpid(), "-", absl::StrJoin(options_.kinds, "+"));
  }
}

StageWorker::~StageWorker() { Drain(std::chrono::milliseconds(0)); }

void StageWorker::Start(std::shared_ptr<grpc::Channel> scheduler) {
  scheduler_ = v1::Scheduler::NewStub(std::move(scheduler));
  thread_ = std::thread([this] { Loop(); });
}

std::string StageWorker::current_job() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return current_job_;
}

void StageWorker::Drain(std::chrono::milliseconds deadline) {
  draining_ = true;
  wake_.notify_all();
  if (!thread_.joinable()) return;
  {
    std::unique_lock<std::mutex> lock(mutex_);
    if (!wake_.wait_for(lock, deadline, [&] { return current_job_.empty(); }) && current_cancel_) {
      spdlog::warn("worker {}: drain deadline reached; handing job {} back", options_.worker_id,
                   current_job_);
      handed_back_ = true;
      current_cancel_->store(true);
    }
  }
  thread_.join();
}

bool StageWorker::SleepUnlessDraining(std::chrono::milliseconds duration) {
  std::unique_lock<std::mutex> lock(mutex_);
  return !wake_.wait_for(lock, duration, [&] { return draining_.load(); });
}

void StageWorker::Loop() {
  spdlog::info("worker {}: leasing {} jobs", options_.worker_id,
               absl::StrJoin(options_.kinds, ", "));
  while (!draining_) {
    v1::LeaseJobRequest request;
    for (const std::string& k : options_.kinds) request.add_kinds(k);
    request.set_worker_id(options_.worker_id);
    request.set_lease_seconds(options_.lease_seconds);
    v1::LeaseJobResponse lease;
    grpc::ClientContext context;
    context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(10));
    const grpc::Status s = scheduler_->LeaseJob(&context, request, &lease);
    if (!s.ok()) {
      spdlog::warn("worker {}: lease failed: {}", options_.worker_id, s.error_message());
      SleepUnlessDraining(std::chrono::milliseconds(options_.poll_interval_ms * 3));
      continue;
    }
    if (!lease.has_job()) {
      SleepUnlessDraining(std::chrono::milliseconds(options_.poll_interval_ms));
      continue;
    }
    if (draining_) {  // leased while the drain began: hand it straight back
      v1::FailJobRequest back;
      back.set_job_id(lease.job().id());
      back.set_lease_token(lease.lease_token());
      back.set_kind(v1::FAILURE_KIND_RELEASED);
      back.set_error(absl::StrCat("handed back by worker ", options_.worker_id, " (draining)"));
      v1::FailJobResponse ignored;
      grpc::ClientContext back_context;
      (void)scheduler_->FailJob(&back_context, back, &ignored);
      break;
    }
    RunJob(lease);
  }
}

absl::StatusOr<store::Digest> StageWorker::FetchInputs(const v1::LeaseJobResponse& lease,
                                                       const ProgressFn& progress,
                                                       pipeline::StageContext* context) {
  const v1::Job& job = lease.job();
  // Scene and inputs, cached by digest: a scene is fetched once per worker, not once per job.
  // Each worker has its own cache (the workers of one process share work_dir).
  const store::Digest scene_digest = rpc::FromProto(job.scene_manifest());
  const fs::path cache = fs::path(options_.work_dir) / absl::StrJoin(options_.kinds, "+");
  const std::string scenes_root = (cache / "scenes").string();
  const std::string results_root = (cache / "results").string();
  context->scene_dir = (fs::path(scenes_root) / scene_digest.hash).string();
  std::set<std::string> keep = {context->scene_dir};
  std::map<std::string, store::Digest> inputs;
  for (const auto& [name, digest] : lease.inputs()) {
    ASSIGN_OR_RETURN(inputs[name], rpc::ParseProtoDigest(digest, absl::StrCat("input ", name)));
    context->inputs[name] = (fs::path(results_root) / digest.hash()).string();
    keep.insert(context->inputs[name]);
  }
  ASSIGN_OR_RETURN(EvictionReport evicted,
                   EvictCache({scenes_root, results_root}, options_.cache_bytes, keep));
  if (!evicted.evicted.empty()) {
    spdlog::info("worker {}: input cache {:.1f} -> {:.1f} MB, evicted {} entries",
                 options_.worker_id, evicted.bytes_before / 1e6, evicted.bytes_after / 1e6,
                 evicted.evicted.size());
  }
  progress({"fetching inputs", 0, 1, 0});
  ASSIGN_OR_RETURN(store::Manifest scene, store::ReadManifest(*store_, scene_digest));
  RETURN_IF_ERROR(
      Annotate(store::MaterializeManifest(*store_, scene, context->scene_dir), "fetching scene"));
  TouchCacheEntry(context->scene_dir);
  for (const auto& [name, digest] : inputs) {
    ASSIGN_OR_RETURN(store::Manifest manifest, store::ReadManifest(*store_, digest));
    RETURN_IF_ERROR(Annotate(store::MaterializeManifest(*store_, manifest, context->inputs[name]),
                             absl::StrCat("fetching input ", name)));
    TouchCacheEntry(context->inputs[name]);
  }
  return scene_digest;
}

absl::StatusOr<store::Digest> StageWorker::UploadOutput(const v1::Job& job,
                                                        const std::string& job_dir,
                                                        const store::Digest& scene, int64_t items) {
  ASSIGN_OR_RETURN(store::Manifest manifest, store::ManifestFromDirectory(job_dir, job.kind()));
  manifest.metadata["job"] = job.id();
  manifest.metadata["scene_manifest"] = scene.ToString();
  if (job.item() >= 0) manifest.metadata["item"] = job.item();
  if (items >= 0) manifest.metadata["items"] = items;
  ASSIGN_OR_RETURN(store::UploadReport report, store::UploadManifest(*store_, manifest, job_dir));
  return report.manifest;
}

absl::Status StageWorker::Execute(const v1::LeaseJobResponse& lease, const std::string& job_dir,
                                  CancelFlag* cancel, const ProgressFn& progress,
                                  store::Digest* output, int64_t* items) {
  const v1::Job& job = lease.job();
  pipeline::StageContext context;
  ASSIGN_OR_RETURN(const store::Digest scene_digest, FetchInputs(lease, progress, &context));
  context.out_dir = job_dir;
  context.parameters = nlohmann::json::parse(job.parameters_json(), nullptr, false);
  if (context.parameters.is_discarded())
    return absl::InvalidArgumentError("job parameters are not JSON");
  context.item = job.item();
  context.num_threads = options_.num_threads;
  context.cancel = cancel;
  context.settings = options_.stage_settings;
  context.memory_budget_bytes = options_.memory_budget_bytes;
  context.progress = progress;
  ASSIGN_OR_RETURN(pipeline::StageResult result, stages_->Run(job.kind(), context));
  RETURN_IF_ERROR(CheckCancelled(cancel, job.kind()));
  *items = result.items;
  progress({"uploading", 0, 1, 0});
  ASSIGN_OR_RETURN(*output, UploadOutput(job, job_dir, scene_digest, result.items));
  return absl::OkStatus();
}

void StageWorker::RunJob(const v1::LeaseJobResponse& lease) {
  const v1::Job& job = lease.job();
  const std::string job_dir =
      (fs::path(options_.work_dir) / "jobs" / absl::StrCat(job.id(), "-a", job.attempts()))
          .string();
  CancelFlag cancel{false};
  {
    std::lock_guard<std::mutex> lock(mutex_);
    current_job_ = job.id();
    current_cancel_ = &cancel;
    handed_back_ = false;
  }
  spdlog::info("worker {}: job {} ({} of scene {}, attempt {})", options_.worker_id, job.id(),
               job.kind(), job.scene(), job.attempts());
  Stopwatch watch;
  JobsRunning().Add({{"stage", job.kind()}}).Increment();
  ProgressTracker progress;
  LeaseHeartbeat heartbeat(scheduler_.get(), lease,
                           std::chrono::milliseconds(options_.heartbeat_interval_ms),
                           options_.worker_id, progress, &cancel);
  std::error_code ec;
  fs::remove_all(job_dir, ec);
  JobOutcome outcome;
  outcome.status = Execute(
      lease, job_dir, &cancel, [&](const pipeline::StageProgress& p) { progress.Update(p); },
      &outcome.output, &outcome.items);
  heartbeat.Stop();
  outcome.lease_lost = heartbeat.lease_lost();
  outcome.cancel_requested = heartbeat.cancel_requested();
  {
    std::lock_guard<std::mutex> lock(mutex_);
    outcome.handed_back = handed_back_;
  }
  const char* label = ReportOutcome(lease, outcome, watch.ElapsedSeconds());
  JobsRunning().Add({{"stage", job.kind()}}).Decrement();
  JobDurations()
      .Add({{"stage", job.kind()}, {"outcome", label}}, metrics::JobBuckets())
      .Observe(watch.ElapsedSeconds());
  fs::remove_all(job_dir, ec);  // outputs live in the store now
  {
    std::lock_guard<std::mutex> lock(mutex_);
    current_job_.clear();
    current_cancel_ = nullptr;
  }
  wake_.notify_all();
}

const char* StageWorker::ReportOutcome(const v1::LeaseJobResponse& lease, const JobOutcome& outcome,
                                       double seconds) {
  const v1::Job& job = lease.job();
  if (outcome.lease_lost) {
    spdlog::warn("worker {}: job {} abandoned (lease lost)", options_.worker_id, job.id());
    return "lease_lost";
  }
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(30));
  grpc::Status reply;
  const char* label = "succeeded";
  if (outcome.status.ok()) {
    v1::CompleteJobRequest request;
    request.set_job_id(job.id());
    request.set_lease_token(lease.lease_token());
    rpc::ToProto(outcome.output, request.mutable_output_manifest());
    request.set_items(outcome.items);
    v1::CompleteJobResponse response;
    reply = scheduler_->CompleteJob(&context, request, &response);
    if (reply.ok()) {
      std::lock_guard<std::mutex> lock(mutex_);
      ++succeeded_;
      counted_.notify_all();
    }
    spdlog::info("worker {}: job {} succeeded in {:.1f} s -> {}", options_.worker_id, job.id(),
                 seconds, outcome.output.ToString());
  } else {
    v1::FailJobRequest request;
    request.set_job_id(job.id());
    request.set_lease_token(lease.lease_token());
    label = SetFailure(outcome.cancel_requested, outcome.handed_back, outcome.status,
                       options_.worker_id, &request);
    v1::FailJobResponse response;
    reply = scheduler_->FailJob(&context, request, &response);
    ++failed_;
    spdlog::warn("worker {}: job {} failed: {}", options_.worker_id, job.id(), request.error());
  }
  if (!reply.ok())
    spdlog::warn("worker {}: reporting job {}: {}", options_.worker_id, job.id(),
                 reply.error_message());
  return label;
}

bool StageWorker::AwaitSucceeded(int64_t count, std::chrono::milliseconds timeout) const {
  std::unique_lock<std::mutex> lock(mutex_);
  return counted_.wait_for(lock, timeout, [&] { return succeeded_ >= count; });
}

void FillWorkerStatus(const worker::StageWorker* worker, const std::vector<std::string>& kinds,
                      v1::WorkerStatus* out) {
  for (const std::string& k : kinds) out->add_kinds(k);
  if (worker == nullptr) {
    out->set_state("serving");
    return;
  }
  out->set_worker_id(worker->worker_id());
  out->set_current_job_id(worker->current_job());
  out->set_jobs_succeeded(worker->succeeded());
  out->set_jobs_failed(worker->failed());
  out->set_state(worker->draining() ? "draining" : "serving");
}

grpc::Status AnswerWorkerStatus(auth::Authenticator* auth, grpc::ServerContext* context,
                                const StageWorker* worker, const std::vector<std::string>& kinds,
                                v1::WorkerStatus* out) {
  absl::StatusOr<auth::Identity> who = auth::Authorize(auth, context, {auth::Role::kAdmin});
  if (!who.ok()) return rpc::ToGrpcStatus(who.status());
  FillWorkerStatus(worker, kinds, out);
  return grpc::Status::OK;
}

}  // namespace instascene::worker
