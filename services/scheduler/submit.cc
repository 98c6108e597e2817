#include "services/scheduler/submit.h"

#include "absl/strings/str_cat.h"
#include "common/core/status.h"
#include "services/pipeline/stages.h"

namespace instascene::scheduler {

absl::StatusOr<std::vector<SubmitResult>> SubmitPipeline(JobQueue& queue,
                                                         const PipelineRequest& request) {
  RETURN_IF_ERROR(store::ValidateDigest(request.scene_manifest));
  const std::vector<std::string> stages =
      request.stages.empty() ? pipeline::DefaultStages() : request.stages;
  if (!request.parameters.is_object())
    return absl::InvalidArgumentError("pipeline parameters must be a JSON object by stage");
  for (const auto& [key, value] : request.parameters.items()) {
    if (std::find(stages.begin(), stages.end(), key) == stages.end())
      return absl::InvalidArgumentError(
          absl::StrCat("parameters given for stage '", key, "', which is not in the pipeline"));
  }
  // Validate everything before queueing anything.
  std::string previous;
  for (const std::string& kind : stages) {
    ASSIGN_OR_RETURN(std::string input, pipeline::StageInput(kind));
    if (input != previous)
      return absl::InvalidArgumentError(absl::StrCat("stage '", kind, "' needs the output of '",
                                                     input.empty() ? "nothing" : input,
                                                     "' right before it"));
    RETURN_IF_ERROR(pipeline::ValidateParameters(
        kind, request.parameters.value(kind, nlohmann::json::object())));
    previous = kind;
  }
  std::vector<SubmitResult> results;
  std::string depends_on;
  for (const std::string& kind : stages) {
    JobSpec spec;
    spec.scene = request.scene.empty() ? request.scene_manifest.hash.substr(0, 12) : request.scene;
    spec.kind = kind;
    spec.parameters = request.parameters.value(kind, nlohmann::json::object());
    spec.scene_manifest = request.scene_manifest;
    spec.depends_on = depends_on;
    spec.priority = request.priority;
    spec.max_attempts = request.max_attempts;
    ASSIGN_OR_RETURN(SubmitResult r, queue.Submit(spec));
    depends_on = r.job.id;
    results.push_back(std::move(r));
  }
  return results;
}

}  // namespace instascene::scheduler
