#include "services/pipeline/local_runner.h"

#include <filesystem>

#include "absl/strings/str_cat.h"
#include "common/core/file_io.h"
#include "common/core/status.h"

#include <nlohmann/json.hpp>

namespace instascene::pipeline {

namespace {
namespace fs = std::filesystem;

// The stage's inputs from the earlier stages' outputs; returns the fan-out source of a
// per-item stage ("" otherwise). A failed item of a joined stage fails the join unless the stage
// takes partial joins (then it runs over the items that succeeded).
absl::StatusOr<std::string> GatherInputs(const PlannedStage& stage, const StageDefinition& def,
                                         const LocalRunResult& result,
                                         const std::map<std::string, int64_t>& item_count,
                                         StageContext* c) {
  std::string each;
  for (const PlannedInput& in : stage.inputs) {
    if (in.mode == InputMode::kOne) {
      c->inputs[in.stage] = result.outputs.at(in.stage);
    } else if (in.mode == InputMode::kEach) {
      each = in.stage;
      c->inputs[in.stage] = result.outputs.at(in.stage);
    } else {
      for (int64_t i = 0; i < item_count.at(in.stage); ++i) {
        const std::string name = absl::StrCat(in.stage, "/", i);
        if (auto failed = result.failures.find(name); failed != result.failures.end()) {
          if (def.spec.partial_join) continue;
          return absl::FailedPreconditionError(
              absl::StrCat(stage.kind, ": input ", name, " failed: ", failed->second.message()));
        }
        c->inputs[name] = result.outputs.at(name);
      }
    }
  }
  return each;
}

// Runs one stage (each of its items for a per-item stage); an item's failure is recorded, its
// output removed, and written to <dir>/failures.json, and the other items run.
absl::Status RunStage(const StageRegistry& registry, const PlannedStage& stage,
                      const StageDefinition& def, const LocalRunOptions& options,
                      std::map<std::string, int64_t>* item_count, LocalRunResult* result) {
  const std::string dir =
      (fs::path(options.out_dir) / (def.spec.directory.empty() ? stage.kind : def.spec.directory))
          .string();
  StageContext c;
  c.scene_dir = options.scene_dir;
  c.parameters = stage.parameters;
  c.num_threads = options.num_threads;
  c.cancel = options.cancel;
  ASSIGN_OR_RETURN(const std::string each, GatherInputs(stage, def, *result, *item_count, &c));
  const int64_t runs = each.empty() ? 1 : result->items.at(each);
  nlohmann::json failures = nlohmann::json::object();
  for (int64_t i = 0; i < runs; ++i) {
    c.item = each.empty() ? -1 : i;
    c.out_dir = each.empty() ? dir : (fs::path(dir) / std::to_string(i)).string();
    c.progress = [&, i = c.item](const StageProgress& p) {
      if (options.progress) options.progress(stage.kind, i, p);
    };
    absl::StatusOr<StageResult> run = registry.Run(stage.kind, c);
    if (!run.ok() && !each.empty() && run.status().code() != absl::StatusCode::kCancelled &&
        !IsCancelled(options.cancel)) {
      std::error_code ec;
      fs::remove_all(c.out_dir, ec);
      result->failures[absl::StrCat(stage.kind, "/", i)] = run.status();
      failures[std::to_string(i)] = run.status().ToString();
      continue;
    }
    if (!run.ok()) return run.status();
    result->outputs[each.empty() ? stage.kind : absl::StrCat(stage.kind, "/", i)] = c.out_dir;
    if (def.spec.fans_out) result->items[stage.kind] = run->items;
  }
  if (!each.empty()) (*item_count)[stage.kind] = runs;
  if (failures.empty()) return absl::OkStatus();
  std::error_code ec;
  fs::create_directories(dir, ec);  // every item may have failed before writing anything
  return WriteFileAtomically((fs::path(dir) / "failures.json").string(), failures.dump(1));
}

}  // namespace

absl::StatusOr<LocalRunResult> RunPipelineLocally(const StageRegistry& registry,
                                                  const std::vector<PlannedStage>& plan,
                                                  const LocalRunOptions& options) {
  LocalRunResult result;
  std::map<std::string, int64_t> item_count;  // per-item stage -> how many jobs it ran
  for (const PlannedStage& stage : plan) {
    const StageDefinition* def = registry.Find(stage.kind);
    if (def == nullptr)
      return absl::InvalidArgumentError(absl::StrCat("unknown stage ", stage.kind));
    RETURN_IF_ERROR(RunStage(registry, stage, *def, options, &item_count, &result));
  }
  return result;
}

}  // namespace instascene::pipeline
