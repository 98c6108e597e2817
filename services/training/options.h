// services/training/options.h: the parameters of the spatial contrastive feature field (paper
// 3.2; ALGORITHM.md section 5), apart from the training code so that the stage's parameter codec
// (stage_params.h) links no rasterizer.
#pragma once

#include <cstdint>
#include <string>

#include "absl/status/statusor.h"
#include "common/core/cancel.h"

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
  // Single-view term: the pixels of a mask the decomposition judged under-segmented (removed from
  // the filtered map) are left out of the term instead of joining the background class as in the
  // released code (default). Better features at 160x120, slightly worse final labels at 320x240
  // (docs/RESULTS.md "Removed masks and the background class").
  bool ignore_removed_masks = false;
  Supervision supervision = Supervision::kFull;
  int pixel_pool = 8192;           // traced pixels cached per view
  bool detach_sample_norm = true;  // as the authors' code (ContrastiveLossOptions::detach_norm)
  uint64_t seed = 1;
  int num_threads = 0;
  const CancelFlag* cancel = nullptr;  // polled per view and step; not owned

  absl::Status Validate() const;
};

}  // namespace instascene::training
