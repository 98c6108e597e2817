// common/raster/projection.h: per-view preprocessing of Gaussians into screen-space splats.
//
// 2DGS: the homogeneous splat-to-pixel transform M = K V H and its screen bounding box
// (ALGORITHM.md 2.2). 3DGS: the Inria EWA projection with 0.3 px dilation. Pixel coordinates here
// put pixel centres at integers (the camera's COLMAP-convention cx, cy minus 0.5), as the CUDA
// rasterizers do. Stateless, thread-safe.
#pragma once

#include <cstdint>
#include <vector>

#include "common/geometry/camera.h"
#include "common/raster/render_types.h"
#include "common/splat/gaussian_cloud.h"

namespace instascene {

inline constexpr int kTileSize = 16;  // BLOCK_X = BLOCK_Y
inline constexpr float kAlphaMin = 1.0f / 255.0f;
inline constexpr float kAlphaMax = 0.99f;
inline constexpr float kTransmittanceMin = 1e-4f;

// One Gaussian projected into one view. Stored array-of-structs: the blend loop reads one splat's
// fields together, so they share cache lines; SIMD runs across pixels, not splats.
struct ProjectedSplat {
  // 2DGS: with M = K V H and its rows Tu, Tv, Tw (Tw . (u, v, 1) is the view depth of splat point
  // (u, v)), the per-pixel planes are k = x Tw - Tu and l = y Tw - Tv. They are stored relative to
  // an integer origin pixel near the splat, tu = ox Tw - Tu and tv = oy Tw - Tv (computed in
  // double), so k = (x - ox) Tw + tu without the float cancellation of the direct form. 3DGS:
  // tu[0..2] = conic (a, b, c) of the inverse 2D covariance; tv, tw unused.
  float tu[3], tv[3], tw[3];
  int32_t origin_px[2];  // 2DGS: (ox, oy)
  float mean_px[2];      // 2DGS: AABB centre (used by the low-pass filter); 3DGS: projected centre
  float opacity;         // sigmoid(logit)
  float depth;           // view-space z of the centre: the per-tile sort key
  float rgb[3];          // SH colour for this view
  float normal_view[3];  // unit normal in camera frame, facing the camera
  int32_t window[4];     // [x0, x1) x [y0, y1): pixels where alpha >= 1/255 is possible
  // [tx0, tx1) x [ty0, ty1): tiles the splat is binned into: the 2DGS/3DGS tile rectangle of its
  // radius (which decides visibility) cut down to the tiles its pixel window touches.
  int32_t tiles[4];
};

struct ProjectionParams {
  float fx, fy, cx, cy;  // cx, cy with pixel centres at integers
  float rotation[9];     // camera_from_world, row-major
  float translation[3];
  float camera_center[3];  // in world
  int width, height, tiles_x, tiles_y;
  float near_plane;
  float scale_modifier;
  int sh_degree;
  float tan_fov_x, tan_fov_y;  // half-width / fx, half-height / fy (3DGS clamping)
};

ProjectionParams MakeProjectionParams(const PinholeCamera& camera, const RenderOptions& options,
                                      int cloud_sh_degree);

// Projects Gaussians [first, first + count) (2DGS surfels) into out[0, count), four at a time
// with SIMD; visible[k] = 0 where Gaussian first + k is culled (then out[k] is undefined). Each
// Gaussian's result does not depend on first or count.
void ProjectSurfels(const GaussianCloud& cloud, size_t first, size_t count,
                    const ProjectionParams& params, ProjectedSplat* out, uint8_t* visible);
// Projects Gaussian i (3DGS ellipsoid, Inria EWA). Returns false when culled.
bool ProjectEllipsoid(const GaussianCloud& cloud, size_t i, const ProjectionParams& params,
                      ProjectedSplat* out);

}  // namespace instascene
