// services/training/vote.h: a training-free baseline (FlashSplat's idea): every Gaussian takes the
// instance that its blending weights vote for across the globally consistent instance maps
// (decomposition masks_sorted), in closed form; a majority for "no instance" leaves it unlabelled.
// Thread-safe (no shared state).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "common/scene/scene.h"
#include "common/splat/gaussian_cloud.h"

namespace instascene::training {

absl::StatusOr<std::vector<uint32_t>> VoteLabels(const Scene& scene, const GaussianCloud& cloud,
                                                 const std::string& decomposition_dir,
                                                 int num_threads = 0);

}  // namespace instascene::training
