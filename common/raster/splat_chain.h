// common/raster/splat_chain.h: the second half of the fast 2DGS backward (tile_backward.h): one
// splat's gradients summed over a view's pixels (with respect to its stored planes, low-pass
// centre, opacity, colour and camera-frame normal) carried to the surfel's parameters: position,
// log-scales, quaternion and opacity logit through the production projection (projection.cc;
// the quaternion's rotation by forward-mode AD), the colour to the SH coefficients and, through
// the view direction, to the position. Internal to the rasterizer; thread-safe.
#pragma once

#include <cstddef>

#include "common/raster/projection.h"
#include "common/raster/surfel_backward.h"
#include "common/splat/gaussian_cloud.h"

namespace instascene {

// Per splat and view: dL / d(k-plane offset tu', l-plane offset tv', Tw, low-pass centre,
// opacity), dL / d rgb and dL / d normal (camera frame, facing the camera), summed over pixels.
struct SplatGrad {
  double tu[3], tv[3], tw[3], mean[2], opacity, rgb[3], normal[3];
};

// Writes surfel g's gradients (from its splat's sums `t` in the view of `params`) into `out`.
void ChainSplatGradient(const GaussianCloud& cloud, size_t g, const ProjectedSplat& s,
                        const ProjectionParams& params, const SplatGrad& t, SurfelGradients* out);

}  // namespace instascene
