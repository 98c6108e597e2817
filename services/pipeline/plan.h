// services/pipeline/plan.h: a planned pipeline as plain data: each stage with its canonical
// parameters and its inputs (which earlier stage, and how). The stage registry produces plans;
// the scheduler's queue core turns them into jobs. Header-only value types.
#pragma once

#include <string>
#include <vector>

#include <nlohmann/json.hpp>

namespace instascene::pipeline {

// How a stage takes one of its inputs.
enum class InputMode {
  kOne,   // the single job of that stage
  kEach,  // one job of this stage per item of that (fan-out) stage's output: a per-item stage
  kAll,   // every per-item job of that stage (fan-in): a join stage
};

inline const char* InputModeName(InputMode mode) {
  switch (mode) {
    case InputMode::kOne:
      return "one";
    case InputMode::kEach:
      return "each";
    case InputMode::kAll:
      return "all";
  }
  return "?";
}

struct PlannedInput {
  std::string stage;
  InputMode mode = InputMode::kOne;
};

struct PlannedStage {
  std::string kind;
  nlohmann::json parameters = nlohmann::json::object();  // canonical
  std::vector<PlannedInput> inputs;                      // stages earlier in the plan
};

}  // namespace instascene::pipeline
