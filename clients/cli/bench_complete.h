// clients/cli/bench_complete.h: `instascene bench complete`, the in-situ completion of one object
// (ISSUE 13's speed figure: ~20k Gaussians, 2000 refinement iterations).
#pragma once

#include <cstdint>

#include "absl/status/status.h"

namespace instascene::cli {

struct CompleteBenchArgs {
  int64_t gaussians = 25000;    // object surfels before the never-seen ones are dropped (~20k stay)
  int iterations = 2000;        // joint refinement iterations
  double lambda_normal = 0.05;  // the refinement's depth-normal consistency weight (0 = off)
  int width = 640, height = 480;
  int threads = 0;
  uint64_t seed = 1;
  bool json = false;
};

absl::Status BenchComplete(const CompleteBenchArgs& args);

}  // namespace instascene::cli
