#include "services/pipeline/registry.h"

#include <algorithm>
#include <filesystem>
#include <new>
#include <set>
#include <stdexcept>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "common/core/status.h"
#include "services/pipeline/memory.h"

namespace instascene::pipeline {

absl::StatusOr<std::string> StageContext::Input(const std::string& name) const {
  auto it = inputs.find(name);
  if (it == inputs.end())
    return absl::InvalidArgumentError(absl::StrCat("the job has no input '", name, "'"));
  return it->second;
}

std::vector<std::string> StageContext::AllInputs(const std::string& stage) const {
  std::vector<std::pair<int64_t, std::string>> items;
  const std::string prefix = stage + "/";
  for (const auto& [name, dir] : inputs) {
    if (name.rfind(prefix, 0) != 0) continue;
    items.emplace_back(std::stoll(name.substr(prefix.size())), dir);
  }
  std::sort(items.begin(), items.end());
  std::vector<std::string> dirs;
  for (auto& [i, dir] : items) dirs.push_back(std::move(dir));
  return dirs;
}

void StageContext::Report(const std::string& phase, int64_t step, int64_t total,
                          double loss) const {
  if (progress) progress(StageProgress{phase, step, total, loss});
}

absl::Status StageRegistry::Add(StageDefinition stage) {
  const StageSpec& spec = stage.spec;
  if (spec.kind.empty() || !spec.canonicalize)
    return absl::InvalidArgumentError("a stage needs a kind and a parameter codec");
  if (Find(spec.kind) != nullptr)
    return absl::AlreadyExistsError(absl::StrCat("stage ", spec.kind, " is registered twice"));
  int fan_inputs = 0;
  for (const PlannedInput& in : spec.inputs) {
    const StageDefinition* source = Find(in.stage);
    if (source == nullptr)
      return absl::InvalidArgumentError(absl::StrCat("stage ", spec.kind, ": input stage ",
                                                     in.stage, " is not registered before it"));
    if (in.mode == InputMode::kEach && !source->spec.fans_out)
      return absl::InvalidArgumentError(absl::StrCat("stage ", spec.kind, " takes each item of ",
                                                     in.stage, ", which does not fan out"));
    fan_inputs += in.mode != InputMode::kOne;
  }
  if (fan_inputs > 1)
    return absl::InvalidArgumentError(
        absl::StrCat("stage ", spec.kind, " has more than one per-item or join input"));
  stages_.push_back(std::move(stage));
  return absl::OkStatus();
}

const StageDefinition* StageRegistry::Find(const std::string& kind) const {
  for (const StageDefinition& s : stages_)
    if (s.spec.kind == kind) return &s;
  return nullptr;
}

std::vector<std::string> StageRegistry::Kinds() const {
  std::vector<std::string> kinds;
  for (const StageDefinition& s : stages_) kinds.push_back(s.spec.kind);
  return kinds;
}

std::vector<std::string> StageRegistry::DefaultStages() const {
  std::vector<std::string> kinds;
  for (const std::string& kind : Kinds())
    if (Find(kind)->spec.in_default_pipeline) kinds.push_back(kind);
  return kinds;
}

std::vector<std::string> StageRegistry::RunnableKinds() const {
  std::vector<std::string> kinds;
  for (const StageDefinition& s : stages_)
    if (s.run) kinds.push_back(s.spec.kind);
  return kinds;
}

absl::StatusOr<nlohmann::json> StageRegistry::Canonicalize(const std::string& kind,
                                                           const nlohmann::json& parameters) const {
  const StageDefinition* stage = Find(kind);
  if (stage == nullptr)
    return absl::InvalidArgumentError(
        absl::StrCat("unknown stage '", kind, "' (", absl::StrJoin(Kinds(), ", "), ")"));
  return stage->spec.canonicalize(parameters);
}

absl::StatusOr<std::vector<PlannedStage>> StageRegistry::Plan(
    std::vector<std::string> stages, const nlohmann::json& parameters) const {
  if (stages.empty()) stages = DefaultStages();
  if (!parameters.is_object())
    return absl::InvalidArgumentError("pipeline parameters must be a JSON object by stage");
  for (const auto& [key, value] : parameters.items()) {
    if (std::find(stages.begin(), stages.end(), key) == stages.end())
      return absl::InvalidArgumentError(absl::StrCat("parameters given for stage '", key,
                                                     "', which is not in the pipeline (",
                                                     absl::StrJoin(stages, ", "), ")"));
  }
  std::vector<PlannedStage> plan;
  std::set<std::string> planned;
  for (const std::string& kind : stages) {
    const StageDefinition* stage = Find(kind);
    if (stage == nullptr)
      return absl::InvalidArgumentError(
          absl::StrCat("unknown stage '", kind, "' (", absl::StrJoin(Kinds(), ", "), ")"));
    if (planned.count(kind))
      return absl::InvalidArgumentError(absl::StrCat("stage ", kind, " appears twice"));
    for (const PlannedInput& in : stage->spec.inputs) {
      if (!planned.count(in.stage))
        return absl::InvalidArgumentError(absl::StrCat("stage '", kind, "' needs the output of '",
                                                       in.stage, "' earlier in the pipeline"));
    }
    ASSIGN_OR_RETURN(nlohmann::json canonical,
                     stage->spec.canonicalize(parameters.value(kind, nlohmann::json::object())));
    plan.push_back({kind, std::move(canonical), stage->spec.inputs});
    planned.insert(kind);
  }
  return plan;
}

absl::StatusOr<StageResult> StageRegistry::Run(const std::string& kind,
                                               const StageContext& context) const {
  const StageDefinition* stage = Find(kind);
  if (stage == nullptr)
    return absl::InvalidArgumentError(absl::StrCat("unknown stage '", kind, "'"));
  if (!stage->run)
    return absl::UnimplementedError(absl::StrCat("this binary cannot run stage ", kind));
  RETURN_IF_ERROR(stage->spec.canonicalize(context.parameters).status());
  for (const PlannedInput& in : stage->spec.inputs) {
    if (in.mode == InputMode::kAll) continue;  // zero items is a valid fan-in
    RETURN_IF_ERROR(context.Input(in.stage).status());
  }
  if (stage->spec.inputs.end() !=
          std::find_if(stage->spec.inputs.begin(), stage->spec.inputs.end(),
                       [](const auto& in) { return in.mode == InputMode::kEach; }) &&
      context.item < 0)
    return absl::InvalidArgumentError(
        absl::StrCat("stage ", kind, " runs per item: no item given"));
  RETURN_IF_ERROR(CheckCancelled(context.cancel, kind));
  if (context.memory_budget_bytes > 0 && stage->estimate) {
    ASSIGN_OR_RETURN(const int64_t need, stage->estimate(context));
    if (need > context.memory_budget_bytes)
      return absl::ResourceExhaustedError(
          absl::StrCat("stage ", kind, " needs about ", need / kMiB,
                       " MiB for this input and parameters, more "
                       "than this worker's budget of ",
                       context.memory_budget_bytes / kMiB,
                       " MiB (--memory-budget-bytes); nothing was allocated"));
  }
  // The one exception boundary of every stage: whatever a stage throws fails its job, never the
  // process that hosts it (an allocation failure is RESOURCE_EXHAUSTED, and not retried).
  absl::StatusOr<StageResult> ran;
  try {
    ran = stage->run(context);
  } catch (const std::bad_alloc&) {
    return absl::ResourceExhaustedError(
        absl::StrCat("stage ", kind, ": out of memory (the input or parameters are too large)"));
  } catch (const std::exception& e) {
    return absl::InternalError(absl::StrCat("stage ", kind, " failed: ", e.what()));
  } catch (...) {
    return absl::InternalError(absl::StrCat("stage ", kind, " failed with an unknown exception"));
  }
  ASSIGN_OR_RETURN(StageResult result, std::move(ran));
  RETURN_IF_ERROR(CheckCancelled(context.cancel, kind));
  if (stage->spec.fans_out && result.items < 0)
    return absl::InternalError(absl::StrCat("stage ", kind, " fans out but reported no items"));
  return result;
}

}  // namespace instascene::pipeline
