// services/scheduler/submit.h: expands a pipeline request (scene + per-stage parameters) into the
// chain of jobs decompose -> train -> segment, each depending on the previous one. Parameters are
// validated by the stage library first, so a bad request queues nothing. Thread-safe.
#pragma once

#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "services/scheduler/job_queue.h"

namespace instascene::scheduler {

struct PipelineRequest {
  store::Digest scene_manifest;
  std::string scene;                                     // "" = the manifest's hash prefix
  nlohmann::json parameters = nlohmann::json::object();  // {"train": {...}, ...}
  int priority = 0;
  std::vector<std::string> stages;  // empty = decompose, train, segment
  int max_attempts = 3;
};

absl::StatusOr<std::vector<SubmitResult>> SubmitPipeline(JobQueue& queue,
                                                         const PipelineRequest& request);

}  // namespace instascene::scheduler
