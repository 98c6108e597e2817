// common/raster/testing/reference_renderer.h: a brute-force, double-precision reference renderer.
//
// Written independently of the optimised rasterizer to test it: Eigen doubles, the ray-splat
// intersection solved as a 3x3 linear system (instead of the homogeneous-plane cross product), and
// for every pixel a fresh depth sort of all Gaussians whose tile rectangle covers the pixel's tile,
// evaluated at every pixel of the tile (no pixel windows). Slow: for tests only.
#pragma once

#include "common/geometry/camera.h"
#include "common/raster/render_types.h"
#include "common/splat/gaussian_cloud.h"

namespace instascene::testing {

// Same outputs as Render (color, alpha, depth, median depth, normal, features, num_contributors,
// visible, full trace with every contribution) for the model the cloud's scale count implies.
RenderResult ReferenceRender(const GaussianCloud& cloud, const PinholeCamera& camera,
                             const RenderOptions& options);

}  // namespace instascene::testing
