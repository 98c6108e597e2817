// services/pipeline/memory.h: what a job will allocate, estimated before it runs. Each stage
// declares an estimate (StageDefinition::estimate) from its inputs' sizes and its parameters; the
// registry refuses a job whose estimate exceeds the worker's budget (StageContext::
// memory_budget_bytes, the node's --memory-budget-bytes) with RESOURCE_EXHAUSTED before the stage
// allocates anything, so a job too large for a worker fails with a message instead of taking the
// process down. Estimates are deliberately on the high side (their constants are measured peaks
// with a margin, docs/RELIABILITY.md "Memory estimates"); they count what the stage allocates,
// not the process's own baseline.
#pragma once

#include <cstdint>
#include <string>

#include "absl/status/statusor.h"

namespace instascene::pipeline {

// Sizes read from a scene folder without loading it: scene.json and the splat's PLY header.
struct SceneFootprint {
  int64_t views = 0;
  int64_t total_pixels = 0;     // over every view
  int64_t max_view_pixels = 0;  // the largest view
  int64_t gaussians = 0;
};
absl::StatusOr<SceneFootprint> ReadSceneFootprint(const std::string& scene_dir);

// The PLY header's vertex count of a splat file (the header only).
absl::StatusOr<int64_t> ReadGaussianCount(const std::string& ply_path);

// The machine's physical memory, the default budget (0 if unknown).
int64_t PhysicalMemoryBytes();

inline constexpr int64_t kMiB = int64_t{1} << 20;

}  // namespace instascene::pipeline
