// services/pipeline/local_runner.h: runs a planned pipeline offline, in this process, with the
// same stage functions and the same DAG the scheduler runs (`instascene run`): stages in plan
// order, per-item stages once per item of their fan-out source, joins over all items. Outputs go
// to <out>/<stage directory>/ and, per item, <out>/<stage directory>/<item>/. As in the services, a
// per-item job that fails fails only its item: its folder is removed, the failure is recorded in
// <out>/<stage directory>/failures.json and in the result, the other items run, and a join over a
// failed item fails. Cancellation and any other stage's failure end the run. Not thread-safe per
// call (stages themselves use `num_threads`).
#pragma once

#include <functional>
#include <map>
#include <string>
#include <vector>

#include "services/pipeline/registry.h"

namespace instascene::pipeline {

struct LocalRunOptions {
  std::string scene_dir, out_dir;
  int num_threads = 0;
  // Progress of one stage (item -1 unless per item).
  std::function<void(const std::string& kind, int64_t item, const StageProgress&)> progress;
  const CancelFlag* cancel = nullptr;
};

struct LocalRunResult {
  // Output directory by dependency name: the kind, or "<kind>/<item>" for per-item stages.
  std::map<std::string, std::string> outputs;
  std::map<std::string, int64_t> items;          // fan-out stages: items reported
  std::map<std::string, absl::Status> failures;  // "<kind>/<item>" of failed per-item jobs
};

absl::StatusOr<LocalRunResult> RunPipelineLocally(const StageRegistry& registry,
                                                  const std::vector<PlannedStage>& plan,
                                                  const LocalRunOptions& options);

}  // namespace instascene::pipeline
