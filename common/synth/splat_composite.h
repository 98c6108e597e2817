// common/synth/splat_composite.h: real-capture composites: several trained splats (e.g. the statues
// and the playbot in ../shared/data/splats) placed side by side in one scene with known
// per-Gaussian instance ids, cameras around them, and everything WriteClutterScene writes.
//
// Real captures come in their own frame and scale (the shared ones are y-down). Each capture is
// scaled so its robust height (2nd-98th percentile) is `object_height`, stood on the plane y = 0
// (y-down: objects extend to negative y) and placed in a row with small gaps and alternating depth
// offsets so that they occlude each other from oblique views. Only scaling and translation are
// applied, so SH colours stay exact (no SH rotation needed). Clouds of mixed SH degree are padded
// to the highest; a mix of 2DGS and 3DGS clouds is converted to surfels. Deterministic.
#pragma once

#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "common/synth/cluttered_scene.h"

namespace instascene {

struct CompositeOptions {
  uint64_t seed = 1;
  int views = 24;
  int width = 160;
  int height = 120;
  float object_height = 0.5f;  // scene units after scaling
  float gap = 0.03f;           // between neighbouring footprints, in object_height units
  float fov_x_deg = 60.0f;
};

// `names` label the objects (e.g. file stems). Fails on empty input or clouds without Gaussians.
absl::StatusOr<ClutterScene> ComposeSplats(const std::vector<GaussianCloud>& clouds,
                                           const std::vector<std::string>& names,
                                           const CompositeOptions& options);

}  // namespace instascene
