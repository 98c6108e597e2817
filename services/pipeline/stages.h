// services/pipeline/stages.h: the pipeline's stages as directory-to-directory functions, the unit
// of work a scheduler job runs and the one code path shared by `instascene run` (offline) and the
// stage workers (services). No gRPC here.
//
//   decompose  scene                       -> decomposition dir (services/decomposition)
//   train      scene + decompose output    -> features + coarse labels (result format)
//   segment    scene + train output        -> final labels, instances/*.ply, instances.json
//
// Parameters are a JSON object per stage; unknown keys and bad values are InvalidArgument, so a bad
// request is refused at submission, before any work is queued. Thread-safe: stateless.
#pragma once

#include <functional>
#include <map>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "absl/status/statusor.h"
#include "common/core/cancel.h"

namespace instascene::pipeline {

// decompose, train, segment: the default pipeline, in dependency order.
const std::vector<std::string>& DefaultStages();
// The stage whose output `kind` consumes ("" for decompose); NotFound for unknown kinds.
absl::StatusOr<std::string> StageInput(const std::string& kind);
absl::Status ValidateParameters(const std::string& kind, const nlohmann::json& parameters);

struct StageProgress {
  std::string phase;
  int64_t step = 0, total = 0;
  double loss = 0;
};

struct StageContext {
  std::string scene_dir;
  std::string input_dir;  // output directory of the stage this one consumes ("" for decompose)
  std::string out_dir;
  nlohmann::json parameters = nlohmann::json::object();
  int num_threads = 0;                                 // 0 = all cores; never changes results
  std::function<void(const StageProgress&)> progress;  // may be null
  const CancelFlag* cancel = nullptr;                  // not owned
};

// Runs one stage. Errors: InvalidArgument for bad input data or parameters (not worth retrying),
// Cancelled when `cancel` was set, others for environment failures (retryable).
absl::Status RunStage(const std::string& kind, const StageContext& context);

}  // namespace instascene::pipeline
