// services/pipeline/stage.h: what a stage is. A stage declares its kind, its named inputs (the
// stages it depends on, and how: one job, per item of a fan-out, or all items together), its
// parameter schema and canonicaliser (one codec, params.h), and, where the binary can run it, its
// run function: a directory-to-directory function shared by `instascene run` (offline) and the
// stage workers (services). No gRPC here; stage libraries provide their StageDefinitions.
#pragma once

#include <cstdint>
#include <functional>
#include <map>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "absl/status/statusor.h"
#include "common/core/cancel.h"
#include "services/pipeline/params.h"
#include "services/pipeline/plan.h"

namespace instascene::pipeline {

struct StageProgress {
  std::string phase;
  int64_t step = 0, total = 0;
  double loss = 0;
};

struct StageContext {
  std::string scene_dir;
  // Output directories of the inputs by dependency name: the input's stage kind, or
  // "<kind>/<item>" for each item of a kAll input.
  std::map<std::string, std::string> inputs;
  std::string out_dir;
  nlohmann::json parameters = nlohmann::json::object();  // decoded by the stage's codec
  int64_t item = -1;                                     // per-item stages: which item
  int num_threads = 0;                                   // 0 = all cores; never changes results
  std::function<void(const StageProgress&)> progress;    // may be null
  const CancelFlag* cancel = nullptr;                    // not owned
  // The worker's deployment settings a stage may need (not job parameters: a client cannot set
  // them). Keys in use: "denoiser" (complete: the diffusion prior's denoiser, grpc://HOST:PORT or
  // onnx:FILE.json).
  std::map<std::string, std::string> settings;
  // The most this job may allocate (bytes; 0 = no limit): a stage whose estimate is larger is
  // refused with RESOURCE_EXHAUSTED before it runs (services/pipeline/memory.h).
  int64_t memory_budget_bytes = 0;

  // The directory of input `name`; InvalidArgument when the job has no such input.
  absl::StatusOr<std::string> Input(const std::string& name) const;
  // The directories of every item of a kAll input over `stage`, in item order.
  std::vector<std::string> AllInputs(const std::string& stage) const;
  void Report(const std::string& phase, int64_t step, int64_t total, double loss = 0) const;
};

struct StageResult {
  int64_t items = -1;  // fan-out stages: how many items the output holds (children per item)
};

using RunFunction = std::function<absl::StatusOr<StageResult>(const StageContext&)>;
// Bytes a job will allocate, from its inputs' sizes and its (canonical) parameters, before it runs.
using MemoryEstimate = std::function<absl::StatusOr<int64_t>(const StageContext&)>;

// The part of a stage every binary can link: no stage library, no heavy dependency.
struct StageSpec {
  std::string kind;
  std::string directory;  // output folder name in `instascene run` (default: the kind)
  std::string description;
  std::vector<PlannedInput> inputs;
  bool fans_out = false;            // its output holds items; per-item stages may take it kEach
  bool in_default_pipeline = true;  // run when no stage list is given
  // A join (kAll input) that runs over the items that succeeded: a failed or cancelled item is
  // left out (absent from StageContext::inputs) instead of failing the join.
  bool partial_join = false;
  // Files every output of this stage holds; the scheduler refuses a completion without them.
  std::vector<std::string> required_outputs;
  std::vector<ParamSpec> parameters;
  std::function<absl::StatusOr<nlohmann::json>(const nlohmann::json&)> canonicalize;
};

// A spec whose parameters and canonicaliser come from `codec` (which must outlive the spec).
template <typename O>
StageSpec MakeStageSpec(std::string kind, std::string directory, std::string description,
                        std::vector<PlannedInput> inputs, bool fans_out,
                        const ParamCodec<O>& codec) {
  StageSpec spec;
  spec.kind = std::move(kind);
  spec.directory = std::move(directory);
  spec.description = std::move(description);
  spec.inputs = std::move(inputs);
  spec.fans_out = fans_out;
  spec.parameters = codec.Schema();
  spec.canonicalize = [&codec](const nlohmann::json& p) { return codec.Canonicalize(p); };
  return spec;
}

struct StageDefinition {
  StageSpec spec;
  RunFunction run;          // null: this binary validates the stage's parameters but cannot run it
  MemoryEstimate estimate;  // null: no estimate (the budget is not checked)
};

}  // namespace instascene::pipeline
