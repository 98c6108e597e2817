// services/generation/refinement.h: joint refinement of a completed object's surfels
// (ALGORITHM.md 7.9, GENERATION.md step 5). Every iteration renders one view (a random one; every
// `fixed_view_every`-th iteration view 0) with the production rasterizer, takes its loss:
//   real views:      L1 inside the mask, the object rendered in situ: with the view's `context`
//                    (the rest of the scene that the view sees, frozen) in front of and behind it,
//                    so the real image is explained everywhere and only what the object changes
//                    matters; + lambda_normal times 2DGS's depth-normal consistency inside the
//                    mask (normal_consistency.h: rendered normals against the normals of the
//                    median depth map);
//   generated views: (1 - lambda_dssim) L1 + lambda_dssim (1 - SSIM) over the image, white
//                    background, + lambda_mask BCE(alpha, mask);
// back-propagates it with the fast 2DGS backward pass (common/raster/tile_backward.h) and takes
// one Adam step on every parameter (position, log-scale, rotation, opacity logit, SH) with the 2DGS
// learning rates (ALGORITHM.md 2.6; the position's decays exponentially, scaled by
// `spatial_scale`). No densification or pruning (the prototype has none either): the surfel count,
// order and every extra channel (provenance) are kept. Deterministic for a given seed and
// thread-count independent. Thread-compatible.
#pragma once

#include <cstdint>
#include <functional>
#include <vector>

#include "absl/status/statusor.h"
#include "common/core/cancel.h"
#include "common/geometry/camera.h"
#include "common/splat/gaussian_cloud.h"

namespace instascene::generation {

struct RefinementView {
  PinholeCamera camera;
  std::vector<float> rgb;     // HxWx3 target in [0, 1]
  std::vector<uint8_t> mask;  // HxW: real views: where the loss applies; generated: BCE target
  bool generated = false;
  float near_plane = 0.01f;  // scene units
  // Frozen surfels rendered together with the object (same SH degree; no gradient reaches them).
  GaussianCloud context;
};

struct RefinementOptions {
  int iterations = 2000;  // the prototype's refineGS
  double lambda_dssim = 0.2;
  double lambda_mask = 0.1;
  double lambda_normal = 0.05;  // 2DGS's normal consistency on the real views; 0 = off
  // 2DGS learning rates; the position's decays from init to final over the iterations and is
  // multiplied by spatial_scale (the scene's camera extent, as 2DGS does).
  double position_lr_init = 1.6e-4, position_lr_final = 1.6e-6, spatial_scale = 1.0;
  double sh_dc_lr = 2.5e-3, sh_rest_lr = 2.5e-3 / 20, opacity_lr = 0.05, scaling_lr = 5e-3,
         rotation_lr = 1e-3;
  int fixed_view_every = 100;  // every n-th iteration renders view 0 (the prototype's rule)
  int curve_every = 100;       // the report's loss curve: mean loss per this many iterations
  uint64_t seed = 1;
  int num_threads = 0;                 // 0 = all cores; never changes results
  const CancelFlag* cancel = nullptr;  // checked between iterations
};

struct RefinementReport {
  int iterations = 0;
  int real_views = 0, generated_views = 0;
  std::vector<double> loss_curve;           // mean loss per curve_every iterations
  double initial_loss = 0, final_loss = 0;  // mean loss over all views before / after
  double seconds = 0;
};

using RefinementProgress = std::function<void(int iteration, int total, double loss)>;

// Refines `cloud` (2DGS) in place. InvalidArgument for views whose images do not match their
// cameras, a 3DGS cloud or bad options; Cancelled when the flag is raised (the cloud is then
// left as it was before the call).
absl::StatusOr<RefinementReport> RefineGaussians(GaussianCloud* cloud,
                                                 const std::vector<RefinementView>& views,
                                                 const RefinementOptions& options,
                                                 const RefinementProgress& progress = nullptr);

}  // namespace instascene::generation
