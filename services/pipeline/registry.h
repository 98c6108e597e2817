// services/pipeline/registry.h: the stage registry. A binary registers, in main, the stages it
// knows: with run functions where it runs them (workers, `instascene run`), as specs only where it
// just validates (the scheduler). Pipelines are planned and parameters canonicalised here, so a
// bad request is refused before anything is queued. Thread-safe after registration (read-only).
#pragma once

#include <map>
#include <string>
#include <vector>

#include "services/pipeline/stage.h"

namespace instascene::pipeline {

class StageRegistry {
 public:
  // AlreadyExists for a second stage of one kind; InvalidArgument when an input names a stage
  // not registered before it, or a kEach input a stage that does not fan out.
  absl::Status Add(StageDefinition stage);
  const StageDefinition* Find(const std::string& kind) const;
  std::vector<std::string> Kinds() const;          // registration order
  std::vector<std::string> RunnableKinds() const;  // those with a run function

  // The default pipeline: every registered stage marked `in_default_pipeline`, in registration
  // order (`export` is asked for explicitly: as a join it fails when any object's completion did).
  std::vector<std::string> DefaultStages() const;

  // Plans a pipeline: `stages` (empty = the default) in dependency order, each with every input
  // it declares, parameters canonicalised by the stage's codec; `parameters` is
  // {"<kind>": {...}, ...} and may only name stages of the pipeline.
  absl::StatusOr<std::vector<PlannedStage>> Plan(std::vector<std::string> stages,
                                                 const nlohmann::json& parameters) const;
  // One stage's parameters, validated and with defaults filled in.
  absl::StatusOr<nlohmann::json> Canonicalize(const std::string& kind,
                                              const nlohmann::json& parameters) const;
  // Runs a stage (NotFound / Unimplemented when this binary cannot).
  absl::StatusOr<StageResult> Run(const std::string& kind, const StageContext& context) const;

 private:
  std::vector<StageDefinition> stages_;
};

}  // namespace instascene::pipeline
