// common/eval/result.h: the result format every segmentation stage writes and `instascene eval`
// reads (docs/EVALUATION.md):
//   <result>/result.json   {"format": "instascene.result/1", "stage": ..., "gaussians": N,
//                           "labels": "labels.ply", "features": "features.ply" | absent,
//                           "feature_dim": D, "instances": [{id, gaussians, centroid, bounds_min,
//                           bounds_max}], ...}
//   <result>/labels.ply    element vertex, property uint instance_id (0 = none), scene order
//   <result>/features.ply  optional: element vertex, properties float f_0 .. f_{D-1} (raw features)
// Value types; thread-safe.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"
#include "common/splat/gaussian_cloud.h"

namespace instascene {

inline constexpr char kResultFormat[] = "instascene.result/1";

struct SegmentationResult {
  std::string stage = "unknown";  // producer: "ground-truth", "decompose", "segment", ...
  std::vector<uint32_t> labels;   // per Gaussian: instance id, 0 = none
  std::vector<float> features;    // optional per-Gaussian features, N x feature_dim
  int feature_dim = 0;
  nlohmann::json metadata = nlohmann::json::object();  // extra keys kept in result.json
};

// Writes the result directory (files atomically). `cloud` supplies positions for the instance
// summaries and must have labels.size() Gaussians.
absl::Status WriteResult(const std::string& directory, const SegmentationResult& result,
                         const GaussianCloud& cloud);
// Reads a result directory; fails unless it has exactly `expected_gaussians` labels.
absl::StatusOr<SegmentationResult> ReadResult(const std::string& directory,
                                              size_t expected_gaussians);

// Per-Gaussian instance ids (a PLY with an `instance_id` vertex property: labels.ply of a
// result, gt/instances.ply of a synthetic scene); fails unless there are `expected_gaussians`
// whole non-negative ids. `source` names the bytes in errors.
absl::StatusOr<std::vector<uint32_t>> ReadGaussianInstanceIds(const std::string& path,
                                                              size_t expected_gaussians);
absl::StatusOr<std::vector<uint32_t>> ParseGaussianInstanceIds(absl::string_view data,
                                                               absl::string_view source,
                                                               size_t expected_gaussians);

}  // namespace instascene
