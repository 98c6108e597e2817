// common/eval/click_eval.h: the click-protocol mIoU of the paper (following Click-Gaussian, with
// Gaussian Grouping's averaging; ALGORITHM.md section 6), plus 3D metrics on per-Gaussian labels.
//
// For each ground-truth object: the reference view is the one where its GT mask is largest; the
// selected instance is, with features, the mean normalised rendered feature inside the GT mask
// (re-normalised), and without features, the most frequent predicted label inside the GT mask.
// In every view where the object is visible (GT mask >= min_visible_pixels) the predicted mask is
// {cos(feature, reference) >= feature_threshold} (features) or {label == selected} (labels), both
// restricted to alpha >= min_alpha; IoU against the GT mask; mean over views, then over objects.
// Thread-safe: no shared state.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "common/eval/metrics.h"
#include "common/eval/result.h"
#include "common/scene/scene.h"

namespace instascene {

struct ClickEvalOptions {
  double feature_threshold = 0.9;    // cosine for feature masks (paper tau_seg)
  float min_alpha = 0.5f;            // pixels below this opacity are never selected
  int min_visible_pixels = 20;       // an object counts as visible in a view from this GT area on
  bool use_features = true;          // use the result's features when it has them
  float observed_min_weight = 0.1f;  // 3D metrics count Gaussians with w above this in some view
  int num_threads = 0;
};

struct ObjectClickScore {
  uint32_t id = 0;
  std::string name;
  int reference_view = -1;
  int views = 0;                // target views where the object is visible
  double miou = 0;              // mean IoU over those views
  uint32_t selected_label = 0;  // label mode only
};

struct ClickEvaluation {
  double miou = 0;  // mean over objects
  bool used_features = false;
  std::vector<ObjectClickScore> objects;
  // 3D metrics are computed over the *observed* Gaussians only: those whose blending weight exceeds
  // observed_min_weight in at least one view. A Gaussian no view shows (the back of an object at
  // a wall, the inside of a cup's base) cannot be segmented from 2D masks by any method.
  InstanceMatch instances;         // 3D, per-Gaussian labels vs ground truth
  double adjusted_rand_index = 0;  // over observed Gaussians (stuff = one cluster)
  size_t observed_gaussians = 0;
};

// gt_masks[v] is the GT instance map of view v; gt_ids the per-Gaussian GT ids; names[id] optional.
absl::StatusOr<ClickEvaluation> EvaluateClicks(const Scene& scene, const GaussianCloud& cloud,
                                               const std::vector<std::vector<uint32_t>>& gt_masks,
                                               const std::vector<uint32_t>& gt_ids,
                                               const SegmentationResult& result,
                                               const std::vector<std::string>& names,
                                               const ClickEvalOptions& options);

// Loads a synthetic scene's ground truth and a result directory, then evaluates.
absl::StatusOr<ClickEvaluation> EvaluateResultDirectory(const std::string& scene_dir,
                                                        const std::string& result_dir,
                                                        const ClickEvalOptions& options);

}  // namespace instascene
