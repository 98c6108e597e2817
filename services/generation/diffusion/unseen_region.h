// services/generation/diffusion/unseen_region.h: the optional "unseen region" estimate of
// ALGORITHM.md 7.8 (the prototype's compute_inpaint_visual_hull) as the diffusion prior's
// generation mask: which pixels of a generated view look at space no real view saw. Per pixel of
// the target: march the ray through the cube centre +- R (R the object radius) from its entry to
// min(exit, the instance hit - a margin); the pixel is unseen when a sample lies in a voxel fewer
// than `min_seen_views` real views saw through (the free-space grid's counts, carved against the
// whole scene). Samples under the support plane are skipped (nothing of the object grows into its
// support). The mask is then cleaned as 7.8 does, erode 10 px then dilate 15 px at the view's full
// resolution (scaled to the grid the mask is computed on; OpenCV's morphology). Deterministic.
#pragma once

#include <cstdint>
#include <vector>

#include "common/geometry/camera.h"
#include "services/generation/free_space.h"
#include "services/generation/object_frame.h"

namespace instascene::generation::diffusion {

struct UnseenOptions {
  int min_seen_views = 3;                // 7.8: voxels seen fewer times are unseen
  float surface_margin_voxels = 2.5f;    // the carving stops 1.5 voxels in front of surfaces
  double erode_px = 10, dilate_px = 15;  // at the view's full width
};

// `camera`: the target on the grid the mask is for (e.g. the latent grid); `instance_depth`: its
// pixels' instance-hit depths (z, 0 = miss; warping.h's WarpResult::depth); `full_width`: the
// width of the view at full resolution (scales the cleaning). Returns HxW 0/1.
std::vector<uint8_t> UnseenRegion(const FreeSpaceGrid& free_space, const ObjectFrame& frame,
                                  const PinholeCamera& camera,
                                  const std::vector<float>& instance_depth, int full_width,
                                  const UnseenOptions& options = {});

}  // namespace instascene::generation::diffusion
