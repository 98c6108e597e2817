// services/generation/normal_consistency.h: 2DGS's depth-normal consistency loss (ALGORITHM.md 2.4
// and 2.6; the joint refinement applies it on the real views inside the mask, 7.9) with its
// gradients with respect to the rendered normal and depth images.
//
// Per pixel, 1 - n_rend . n_surf, where n_rend is the rendered normal (world frame, the
// alpha-blended unit normals, not normalised: Render's `normal`) and n_surf the normal of the
// surface the depth map describes: the pixel's neighbours back-projected with their depth
// (camera z; pixel centres as in camera.h) give the normalised cross product of the central
// differences (P(x, y+1) - P(x, y-1)) x (P(x+1, y) - P(x-1, y)), which faces the camera, times the
// pixel's alpha (a constant: 2DGS detaches it). InstaScene uses the median depth (depth_ratio 1).
// Two deviations from 2DGS, both where its surface normal is meaningless: a pixel with a neighbour
// of depth 0 (nothing hit; 2DGS back-projects it to the camera centre) has n_surf = 0, as border
// pixels have in 2DGS; and the intrinsics are the camera's own, not a centred principal point.
// Stateless, thread-safe.
#pragma once

#include <cstdint>
#include <vector>

#include "absl/status/statusor.h"
#include "common/geometry/camera.h"

namespace instascene::generation {

// Mean over the masked pixels (mask[i] != 0; every pixel when `mask` is empty) of
// 1 - n_rend . n_surf; 0 when no pixel is masked. Adds `weight` times its gradient into d_normal
// (HxWx3) and d_depth (HxW). normal: HxWx3, depth and alpha: HxW, all of the camera's size;
// InvalidArgument (naming the buffer and both sizes) for any other size or a null gradient.
absl::StatusOr<double> NormalConsistency(const std::vector<float>& normal,
                                         const std::vector<float>& depth,
                                         const std::vector<float>& alpha,
                                         const std::vector<uint8_t>& mask,
                                         const PinholeCamera& camera, double weight,
                                         std::vector<float>* d_normal, std::vector<float>* d_depth);

}  // namespace instascene::generation
