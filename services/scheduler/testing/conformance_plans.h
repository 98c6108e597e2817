// services/scheduler/testing/conformance_plans.h: the job kinds, outputs and stage plans the
// queue conformance suite's files (queue_conformance.cc, queue_conformance_dag.cc) submit. Not
// for backends' tests: they include queue_conformance.h.
#pragma once

#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "common/store/digest.h"
#include "services/scheduler/job_queue.h"

namespace instascene::scheduler::testing {

inline const std::vector<std::string> kAll = {"decompose", "train", "segment", "item", "join"};

inline store::Digest Out(const std::string& what) { return store::ComputeDigest(what); }

inline PlannedStage Stage(const std::string& kind, std::vector<PlannedInput> inputs = {},
                          nlohmann::json parameters = {{"p", 1}}) {
  return {kind, std::move(parameters), std::move(inputs)};
}

// decompose -> train -> segment (fans out) -> item per instance -> join over all items.
inline std::vector<PlannedStage> FanOutPipeline(const nlohmann::json& item_parameters = {
                                                    {"p", 1}}) {
  return {Stage("decompose"), Stage("train", {{"decompose", InputMode::kOne}}),
          Stage("segment", {{"train", InputMode::kOne}}),
          Stage("item", {{"segment", InputMode::kEach}, {"decompose", InputMode::kOne}},
                item_parameters),
          Stage("join", {{"item", InputMode::kAll}})};
}

}  // namespace instascene::scheduler::testing
