// common/raster/surfel_backward.h: a differentiable 2DGS renderer for refinement (ALGORITHM.md 7.9:
// the joint refinement of completed objects needs gradients for colour/SH, opacity, position,
// scale and rotation).
//
// The forward pass is the 2DGS model of the production rasterizer (ALGORITHM.md 2: ray-splat
// intersection through the homogeneous planes of M = K V H, the min of the 3D and the 2D low-pass
// distance, alpha = min(0.99, opacity * G), skip alpha < 1/255, stop at T < 1e-4, front to back by
// centre depth, the low-pass filter centred on the 3-sigma footprint's screen box) written once
// for clarity, in double precision, one pixel at a time. It is the reference the fast backward
// (tile_backward.h) is tested against. The backward pass walks each pixel's list back to front
// (the standard alpha-compositing
// adjoint) and differentiates the per-pixel alpha with forward-mode automatic differentiation
// (Eigen's AutoDiffScalar over the 10 geometric parameters of the surfel), so the maths is not
// hand-derived twice. SH degree 0 and 1 (the colour's dependence on the position through the view
// direction is included). Surfels are binned into 16x16 tiles by a conservative pixel box; rows
// (forward) and 16-row bands (backward, each with its own accumulators summed in band order) run in
// parallel, so results do not depend on the thread count. Tests compare it with finite
// differences for every parameter.
#pragma once

#include <vector>

#include "absl/status/statusor.h"
#include "common/geometry/camera.h"
#include "common/splat/gaussian_cloud.h"

namespace instascene {

struct SurfelRenderOptions {
  float background[3] = {1.0f, 1.0f, 1.0f};
  float near_plane = 0.01f;  // scene units
  // The forward's cut-offs (skip alpha < 1/255, stop at T < 1e-4) are steps: a finite difference
  // across one sees a jump the gradient (rightly) does not. false = no cut-offs and every pixel
  // considered: a smooth model for gradient checks.
  bool cutoffs = true;
};

struct SurfelImage {
  int width = 0, height = 0;
  std::vector<float> color;  // HxWx3
  std::vector<float> alpha;  // HxW
};

// Gradients in the layout of GaussianCloud's arrays (same sizes).
struct SurfelGradients {
  std::vector<float> positions, log_scales, rotations, opacity_logits, sh;
  static SurfelGradients Zeros(const GaussianCloud& cloud);  // every array sized, all 0
};

// Forward. Fails on a cloud that is not 2DGS, has SH degree > 1, or an invalid camera.
absl::StatusOr<SurfelImage> RenderSurfelsDifferentiable(const GaussianCloud& cloud,
                                                        const PinholeCamera& camera,
                                                        const SurfelRenderOptions& options);

// sum(weight_color . color) + sum(weight_alpha . alpha) of the forward image, accumulated in double
// (the loss a finite-difference check differentiates; weight_alpha may be empty).
absl::StatusOr<double> WeightedImageSum(const GaussianCloud& cloud, const PinholeCamera& camera,
                                        const SurfelRenderOptions& options,
                                        const std::vector<float>& weight_color,
                                        const std::vector<float>& weight_alpha);

// Backward: given dL/dcolor (HxWx3) and dL/dalpha (HxW, may be empty), the gradient of L with
// respect to every parameter of every surfel.
absl::StatusOr<SurfelGradients> SurfelBackward(const GaussianCloud& cloud,
                                               const PinholeCamera& camera,
                                               const SurfelRenderOptions& options,
                                               const std::vector<float>& dloss_dcolor,
                                               const std::vector<float>& dloss_dalpha);

}  // namespace instascene
