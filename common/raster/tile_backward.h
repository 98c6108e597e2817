// common/raster/tile_backward.h: the fast 2DGS backward pass, on the production rasterizer's own
// forward (ALGORITHM.md 7.9: the joint refinement needs gradients for colour/SH, opacity,
// position, scale and rotation, thousands of times per object).
//
// The forward is Render (rasterizer.h) with contributor tracing (weights w = alpha T; the
// transmittance is recovered as T_{k+1} = T_k - w_k), so the
// backward differentiates exactly the model that produced the image (float, the box-centre
// low-pass filter, every cut-off). The backward walks each pixel's traced list back to front (the
// alpha-compositing adjoint) and differentiates the per-pixel alpha analytically with respect to
// the splat's stored planes (k = x Tw - Tu, l = y Tw - Tv), its low-pass centre and its opacity;
// those per-splat sums are then carried to the surfel's 10 geometric parameters once per surfel
// by forward-mode automatic differentiation of the projection (Eigen's AutoDiffScalar), and the
// colour sums to the SH coefficients (any degree 0-3) and, through the view direction, to the
// position. The normal and median-depth images (the depth-normal consistency term of 2DGS) have
// adjoints too: the normal is one more composited channel (each splat's unit normal facing the
// camera, background 0) whose splat sums go to the rotation; the median depth is the depth, at the
// pixel, of the last contributor with transmittance > 0.5 before it, so its adjoint goes to that
// splat's planes (the ray-splat intersection's depth, or its centre depth under the low-pass
// filter). The slow double-precision kernel (surfel_backward.h) is the reference it is tested
// against; finite differences check the degree-2/3 colour terms. Rows run in 16-row bands with
// their own accumulators summed in band order: results do not depend on the thread count.
// Thread-safe (no shared mutable state).
#pragma once

#include <span>
#include <vector>

#include "absl/status/statusor.h"
#include "common/geometry/camera.h"
#include "common/raster/render_types.h"
#include "common/raster/surfel_backward.h"
#include "common/splat/gaussian_cloud.h"

namespace instascene {

// Renders a 2DGS cloud with what the backward needs (colour, alpha, the full contributor trace);
// `options` chooses background, near plane, SH degree, threads, workspace, and may ask for
// depth/normals too. Fails on a 3DGS cloud or invalid camera/options.
absl::StatusOr<RenderResult> RenderForBackward(const GaussianCloud& cloud,
                                               const PinholeCamera& camera,
                                               const RenderOptions& options);

// dL/d of the forward's images; an empty span = L does not depend on that image.
struct ImageAdjoints {
  std::span<const float> color;         // HxWx3
  std::span<const float> alpha;         // HxW
  std::span<const float> normal;        // HxWx3, world frame, as Render's `normal` (unnormalised)
  std::span<const float> median_depth;  // HxW, as Render's `median_depth`
};

// Gradients of a loss L with respect to every parameter of every surfel, given dL/dcolor (HxWx3)
// and dL/dalpha (HxW, may be empty) at the image `forward` that RenderForBackward made from the
// same cloud, camera and options. The SH gradient covers the coefficients the forward used
// (options.max_sh_degree); the others get 0. With options.workspace set, it must be the workspace
// the forward rendered with, not used since: its projected splats are reused.
absl::StatusOr<SurfelGradients> TileBackward(const GaussianCloud& cloud,
                                             const PinholeCamera& camera,
                                             const RenderOptions& options,
                                             const RenderResult& forward,
                                             const std::vector<float>& dloss_dcolor,
                                             const std::vector<float>& dloss_dalpha);
// The same for any of the four images (each adjoint empty or of the image's size).
absl::StatusOr<SurfelGradients> TileBackward(const GaussianCloud& cloud,
                                             const PinholeCamera& camera,
                                             const RenderOptions& options,
                                             const RenderResult& forward,
                                             const ImageAdjoints& adjoints);

}  // namespace instascene
