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

namespace instascene::training {

// The rows of the paper's Table 2.
enum class Supervision {
  kNoisy2d,       // single-view term on the raw 2D masks only
  k3d,            // 3D term only
  k3dFiltered2d,  // 3D + single-view on the filtered masks
  kFull,          // 3D + filtered single-view + cross-view on the consistent instance maps
};
absl::StatusOr<Supervision> ParseSupervision(
    const std::string& name);  // noisy2d, 3d, 3d+filtered2d, full

struct TrainingOptions {
  int feature_dim = 16;           // D
  int iterations = 1500;          // optimisation steps (paper: 10000 on a GPU; see docs/RESULTS.md)
  int samples = 4096;             // samples per term and step (paper: 32768)
  float learning_rate = 0.025f;   // Adam, eps 1e-15, betas 0.9 / 0.999
  double lambda_single = 0.5e-6;  // 1e-6 x the 0.5 branch weight of the code
  double lambda_multi = 1e-6;
  double lambda_3d = 2.5e-6;
  int multi_view_every = 10;      // the cross-view term runs every this many steps
  int multi_view_window = 5;      // consecutive views (name order) pooled by the cross-view term
  bool consider_negative = true;  // single-view term: unlabelled pixels form a background class
  Supervision supervision = Supervision::kFull;
  int pixel_pool = 8192;           // traced pixels cached per view
  bool detach_sample_norm = true;  // as the authors' code (ContrastiveLossOptions::detach_norm)
  uint64_t seed = 1;
  int num_threads = 0;
  const CancelFlag* cancel = nullptr;  // polled per view and step; not owned

  absl::Status Validate() const;
};

// Per-view cached supervision.
struct ViewData {
  std::vector<uint64_t> offsets;                                  // pool pixel -> contributor range
  std::vector<uint32_t> gaussians;                                // contributors
  std::vector<float> weights;                                     // their blending weights
  std::vector<uint32_t> raw_label, filtered_label, sorted_label;  // per pool pixel
  std::vector<uint32_t> visible_labelled;  // Gaussians visible in the view with a 3D label
};

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
