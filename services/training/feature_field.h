// services/training/feature_field.h: the spatial contrastive feature field (paper 3.2, Eq. 4, 7-8;
// ALGORITHM.md section 5): a D-dimensional feature per Gaussian, all other attributes frozen,
// trained with the three contrastive terms and Adam.
//
// Geometry is frozen, so rendered features are linear in the (normalised) per-Gaussian features:
// E(p) = sum_k w_k(p) f^_k. PrepareTraining renders every view once and caches the contributor
// lists of a fixed random pool of pixels per view; training then computes features, loss and the
// exact gradient (scatter-add of w dL/dE, through the normalisation) from those lists alone.
// Deterministic from the seed and independent of the thread count. Not thread-safe per object.
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "common/core/cancel.h"
#include "common/scene/scene.h"
#include "common/splat/gaussian_cloud.h"
#include "services/training/options.h"

namespace instascene::training {

// Per-view cached supervision.
struct ViewData {
  std::vector<uint64_t> offsets;                                  // pool pixel -> contributor range
  std::vector<uint32_t> gaussians;                                // contributors
  std::vector<float> weights;                                     // their blending weights
  std::vector<uint32_t> raw_label, filtered_label, sorted_label;  // per pool pixel
  std::vector<uint32_t> visible_labelled;  // Gaussians visible in the view with a 3D label
};

// A single-view label that takes no part in the term (ignore_removed_masks).
inline constexpr uint32_t kIgnoredLabel = 0xffffffffu;

struct TrainingData {
  size_t num_gaussians = 0;
  std::vector<ViewData> views;
  std::vector<uint32_t> labels3d;  // per Gaussian: coarse instance + 1, 0 = none (fixed convention)
};

// Reads the decomposition outputs (labels.ply, masks_filtered/, masks_sorted/) and the scene masks.
absl::StatusOr<TrainingData> PrepareTraining(
    const Scene& scene, const GaussianCloud& cloud, const std::string& decomposition_dir,
    const TrainingOptions& options, const std::function<void(int, int)>& progress = nullptr);

struct TrainingResult {
  std::vector<float> features;  // raw (unnormalised), N x D
  std::vector<double> loss;     // per step
  double seconds = 0;
};

absl::StatusOr<TrainingResult> TrainFeatures(
    const TrainingData& data, const TrainingOptions& options,
    const std::function<void(int step, int total, double loss)>& progress = nullptr);

// The training loss and its gradient for given features (exposed for the gradient test): one step's
// terms for view `view` (single-view and 3D, plus cross-view when `with_multi_view`), with fixed
// sample indices drawn from `seed`.
double LossAndGradient(const TrainingData& data, const TrainingOptions& options,
                       const std::vector<float>& features, int view, bool with_multi_view,
                       uint64_t seed, std::vector<double>* grad);

}  // namespace instascene::training
