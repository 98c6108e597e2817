// JobQueue: submissions (pipelines checked and placed; jobs created now, or per item when a
// fan-out source completes, from the plan deferred on it).
#include "services/scheduler/job_queue.h"

#include <algorithm>
#include <map>

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

// A failed or cancelled job submitted again starts afresh: no attempts, error, cancellation,
// backoff or progress; the new request's priority and attempt budget.
void ResetForResubmit(const SubmitRequest& request, int pending, Job* job) {
  job->attempts = 0;
  job->error.clear();
  job->cancel_requested = false;
  job->not_before_ms = 0;
  job->progress = {};
  job->pending = pending;
  job->priority = request.priority;
  job->max_attempts = request.max_attempts;
}

}  // namespace

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
      ResetForResubmit(request, pending, &*existing);
      RETURN_IF_ERROR(tx.Update(*existing));
      return SubmitResult{*std::move(existing), false, true};
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
    return CheckTenantLimit(tx, request.scene, results);
  }));
  return results;
}

absl::Status JobQueue::CheckTenantLimit(QueueTx& tx, const std::string& scene,
                                        const std::vector<SubmitResult>& results) {
  const std::string tenant = auth::SceneTenant(scene);
  const int64_t added = std::count_if(results.begin(), results.end(), [](const SubmitResult& r) {
    return r.created || r.requeued;
  });
  if (options_.max_unfinished_per_tenant == 0 || tenant.empty() || added == 0)
    return absl::OkStatus();
  ASSIGN_OR_RETURN(const int64_t unfinished, tx.CountUnfinished(tenant + ":"));
  if (unfinished <= options_.max_unfinished_per_tenant) return absl::OkStatus();
  return absl::ResourceExhaustedError(absl::StrCat(
      "tenant ", tenant, " would hold ", unfinished, " unfinished jobs with this submission's ",
      added, ", over its limit of ", options_.max_unfinished_per_tenant,
      " (the scheduler's --max-unfinished-jobs-per-tenant); nothing was submitted: wait for "
      "jobs to finish or cancel some"));
}

}  // namespace instascene::scheduler
