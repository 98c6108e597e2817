// common/synth/observed_surfels.h: what a real capture would have reconstructed. A synthetic
// scene's surfels cover every surface, also the backs and undersides no camera sees; a 2DGS model
// trained on real images has nothing there. For completion experiments (issue 13) those surfels
// are dropped: a surfel survives when it contributes a blending weight above `min_weight` to some
// pixel of some view. Deterministic; thread-count independent.
#pragma once

#include "absl/status/status.h"
#include "common/synth/cluttered_scene.h"

namespace instascene {

// Removes never-seen surfels from scene->cloud / instance_ids and updates each object's
// first_gaussian / num_gaussians (object surfels stay contiguous and in order), keeping each
// object's complete surfels in scene->complete_surfels. The meshes (ground truth) are unchanged.
absl::Status DropUnseenSurfels(ClutterScene* scene, float min_weight = 0.01f, int num_threads = 0);

}  // namespace instascene
