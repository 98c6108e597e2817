#include "services/scheduler/job_queue.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <set>

#include "absl/strings/str_cat.h"
#include "common/auth/identity.h"
#include "common/core/status.h"

namespace instascene::scheduler {
namespace {

// A deferred stage of a plan, as stored on its fan-out source.
struct PlanStage {
  std::string kind, mode, over;  // mode "each" (per item) or "all" (join over per-item `over`)
  nlohmann::json parameters;
  std::vector<JobDependency> fixed;  // kOne inputs on submitted jobs
};

nlohmann::json PlanStageJson(const PlanStage& s) {
  nlohmann::json fixed = nlohmann::json::object();
  for (const JobDependency& d : s.fixed) fixed[d.name] = d.job_id;
  return {{"kind", s.kind},
          {"mode", s.mode},
          {"over", s.over},
          {"parameters", s.parameters},
          {"fixed", fixed}};
}

absl::StatusOr<PlanStage> ParsePlanStage(const nlohmann::json& j) {
  if (!j.is_object() || !j.contains("kind") || !j.contains("mode") || !j.contains("fixed"))
    return absl::DataLossError(absl::StrCat("malformed fan-out plan entry ", j.dump()));
  PlanStage s;
  s.kind = j["kind"].get<std::string>();
  s.mode = j["mode"].get<std::string>();
  s.over = j.value("over", "");
  s.parameters = j.value("parameters", nlohmann::json::object());
  for (const auto& [name, id] : j["fixed"].items())
    s.fixed.push_back({name, id.get<std::string>()});
  return s;
}

}  // namespace

absl::Status QueueOptions::Validate() const {
  if (min_lease_ms <= 0 || lease_ms < min_lease_ms || max_lease_ms < lease_ms)
    return absl::InvalidArgumentError("leases: need 0 < min_lease_ms <= lease_ms <= max_lease_ms");
  if (backoff_base_ms < 0 || backoff_cap_ms < backoff_base_ms)
    return absl::InvalidArgumentError("backoff: need 0 <= base <= cap");
  if (backoff_jitter < 0 || backoff_jitter >= 1)
    return absl::InvalidArgumentError("backoff_jitter must be in [0, 1)");
  if (max_items < 0) return absl::InvalidArgumentError("max_items must be >= 0");
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

absl::StatusOr<SubmitResult> JobQueue::SubmitOne(QueueTx& tx, const SubmitRequest& request,
                                                 const std::string& kind,
                                                 const nlohmann::json& parameters,
                                                 std::vector<JobDependency> dependencies,
                                                 const std::string& parent, int64_t item) {
  std::sort(dependencies.begin(), dependencies.end(),
            [](const JobDependency& a, const JobDependency& b) { return a.name < b.name; });
  std::vector<std::pair<std::string, std::string>> keys;
  int pending = 0;
  const bool partial = options_.partial_join_kinds.count(kind) > 0;
  for (const JobDependency& d : dependencies) {
    ASSIGN_OR_RETURN(Job dep, Load(tx, d.job_id));
    keys.emplace_back(d.name, dep.key);
    const bool left_out = partial && d.name.find('/') != std::string::npos &&
                          (dep.state == JobState::kFailed || dep.state == JobState::kCancelled);
    pending += dep.state != JobState::kSucceeded && !left_out;
  }
  const std::string key = JobKey(request.scene_manifest, kind, parameters, keys, item,
                                 auth::SceneTenant(request.scene));
  const std::string id = JobIdFromKey(key);
  ASSIGN_OR_RETURN(std::optional<Job> existing, tx.Get(id));
  if (existing) {
    if (existing->state == JobState::kFailed || existing->state == JobState::kCancelled) {
      RETURN_IF_ERROR(Apply(&*existing, JobEvent::kResubmit));
      existing->attempts = 0;
      existing->error.clear();
      existing->cancel_requested = false;
      existing->not_before_ms = 0;
      existing->progress = {};
      existing->pending = pending;
      existing->priority = request.priority;
      existing->max_attempts = request.max_attempts;
      RETURN_IF_ERROR(tx.Update(*existing));
    }
    return SubmitResult{*std::move(existing), false};
  }
  Job j;
  j.id = id;
  j.key = key;
  j.scene = request.scene;
  j.kind = kind;
  j.parameters_json = parameters.dump();
  j.scene_manifest = request.scene_manifest;
  j.dependencies = std::move(dependencies);
  j.parent = parent;
  j.item = item;
  j.pending = pending;
  j.priority = request.priority;
  j.max_attempts = request.max_attempts;
  j.created_ms = j.updated_ms = clock_->NowMs();
  RETURN_IF_ERROR(tx.Insert(j));
  return SubmitResult{std::move(j), true};
}

absl::Status JobQueue::Expand(QueueTx& tx, const Job& source, const nlohmann::json& plan,
                              std::vector<SubmitResult>* results) {
  if (source.items < 0)
    return absl::FailedPreconditionError(
        absl::StrCat("job ", source.id, " (", source.kind,
                     ") succeeded without reporting its items; per-item stages cannot follow it"));
  SubmitRequest request;
  request.scene = source.scene;
  request.scene_manifest = source.scene_manifest;
  request.priority = plan.value("priority", source.priority);
  request.max_attempts = plan.value("max_attempts", source.max_attempts);
  std::map<std::string, std::vector<std::string>> per_item;  // kind -> job id per item
  for (const nlohmann::json& entry : plan.value("stages", nlohmann::json::array())) {
    ASSIGN_OR_RETURN(PlanStage stage, ParsePlanStage(entry));
    if (stage.mode == "each") {
      std::vector<std::string>& ids = per_item[stage.kind];
      for (int64_t i = 0; i < source.items; ++i) {
        std::vector<JobDependency> deps = stage.fixed;
        deps.push_back({source.kind, source.id});
        ASSIGN_OR_RETURN(SubmitResult r, SubmitOne(tx, request, stage.kind, stage.parameters,
                                                   std::move(deps), source.id, i));
        ids.push_back(r.job.id);
        results->push_back(std::move(r));
      }
    } else {
      auto it = per_item.find(stage.over);
      if (it == per_item.end())
        return absl::DataLossError(absl::StrCat("fan-out plan of job ", source.id, ": stage ",
                                                stage.kind, " joins unknown stage ", stage.over));
      std::vector<JobDependency> deps = stage.fixed;
      for (size_t i = 0; i < it->second.size(); ++i)
        deps.push_back({absl::StrCat(stage.over, "/", i), it->second[i]});
      ASSIGN_OR_RETURN(SubmitResult r, SubmitOne(tx, request, stage.kind, stage.parameters,
                                                 std::move(deps), source.id, -1));
      results->push_back(std::move(r));
    }
  }
  return absl::OkStatus();
}

namespace {

// Where each stage of a submission goes: submitted now, created per item when a fan-out stage
// completes, or a join of such per-item stages.
struct Placement {
  std::string source;  // "" = submitted now; else the fan-out stage whose completion creates it
  std::string over;    // joins: the per-item stage they wait for
};

// The stages classified; InvalidArgument for a stage without a kind, one that appears twice,
// parameters that are not an object, an input not earlier in the pipeline, and fan-out inputs
// taken one way they cannot be (a per-item input taken as one, two fan-out inputs, a nested
// fan-out, a join over what is not per item).
absl::StatusOr<std::map<std::string, Placement>> PlaceStages(const SubmitRequest& request) {
  std::map<std::string, Placement> placed;
  for (const PlannedStage& stage : request.stages) {
    if (stage.kind.empty()) return absl::InvalidArgumentError("a stage has no kind");
    if (placed.count(stage.kind))
      return absl::InvalidArgumentError(absl::StrCat("stage ", stage.kind, " appears twice"));
    if (!stage.parameters.is_object())
      return absl::InvalidArgumentError(
          absl::StrCat("stage ", stage.kind, ": parameters must be a JSON object"));
    Placement p;
    for (const PlannedInput& in : stage.inputs) {
      auto it = placed.find(in.stage);
      if (it == placed.end())
        return absl::InvalidArgumentError(absl::StrCat("stage ", stage.kind, " needs stage ",
                                                       in.stage, " earlier in the pipeline"));
      const bool input_fixed = it->second.source.empty();
      if (in.mode == InputMode::kOne && !input_fixed)
        return absl::InvalidArgumentError(
            absl::StrCat("stage ", stage.kind, ": input ", in.stage,
                         " is created per fan-out; take it per item or all together"));
      if (in.mode != InputMode::kOne) {
        if (!p.source.empty())
          return absl::InvalidArgumentError(
              absl::StrCat("stage ", stage.kind, " has more than one fan-out input"));
        if (in.mode == InputMode::kEach && !input_fixed)
          return absl::InvalidArgumentError(
              absl::StrCat("stage ", stage.kind, ": nested fan-out over ", in.stage));
        if (in.mode == InputMode::kAll && (input_fixed || !it->second.over.empty()))
          return absl::InvalidArgumentError(absl::StrCat("stage ", stage.kind, ": ", in.stage,
                                                         " is not a per-item stage to join"));
        p.source = in.mode == InputMode::kEach ? in.stage : it->second.source;
        if (in.mode == InputMode::kAll) p.over = in.stage;
      }
    }
    placed[stage.kind] = p;
  }
  return placed;
}

}  // namespace

absl::StatusOr<std::vector<SubmitResult>> JobQueue::Submit(const SubmitRequest& request) {
  RETURN_IF_ERROR(store::ValidateDigest(request.scene_manifest));
  if (request.stages.empty()) return absl::InvalidArgumentError("submission has no stages");
  if (request.max_attempts < 1) return absl::InvalidArgumentError("max_attempts must be >= 1");
  ASSIGN_OR_RETURN(const auto placed, PlaceStages(request));
  std::vector<SubmitResult> results;
  RETURN_IF_ERROR(store_->Transact(false, [&](QueueTx& tx) -> absl::Status {
    results.clear();
    std::map<std::string, std::string> fixed_ids;  // kind -> job id of submitted stages
    std::map<std::string, nlohmann::json> plans;   // fan-out source kind -> deferred stages
    for (const PlannedStage& stage : request.stages) {
      const Placement& p = placed.at(stage.kind);
      std::vector<JobDependency> fixed;
      for (const PlannedInput& in : stage.inputs)
        if (in.mode == InputMode::kOne) fixed.push_back({in.stage, fixed_ids.at(in.stage)});
      if (p.source.empty()) {
        ASSIGN_OR_RETURN(SubmitResult r,
                         SubmitOne(tx, request, stage.kind, stage.parameters, fixed, "", -1));
        fixed_ids[stage.kind] = r.job.id;
        results.push_back(std::move(r));
        continue;
      }
      PlanStage deferred{stage.kind, p.over.empty() ? "each" : "all", p.over, stage.parameters,
                         fixed};
      plans[p.source]["stages"].push_back(PlanStageJson(deferred));
    }
    for (auto& [source_kind, plan] : plans) {
      plan["priority"] = request.priority;
      plan["max_attempts"] = request.max_attempts;
      ASSIGN_OR_RETURN(Job source, Load(tx, fixed_ids.at(source_kind)));
      if (std::find(source.plans.begin(), source.plans.end(), plan) == source.plans.end()) {
        source.plans.push_back(plan);
        RETURN_IF_ERROR(tx.Update(source));
      }
      if (source.state == JobState::kSucceeded) RETURN_IF_ERROR(Expand(tx, source, plan, &results));
    }
    return absl::OkStatus();
  }));
  return results;
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
    ASSIGN_OR_RETURN(pruned, tx.DeleteFinishedBefore(clock_->NowMs() - retention_ms));
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
