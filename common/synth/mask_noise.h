// common/synth/mask_noise.h: a simulated class-agnostic 2D segmenter (the `masks/` of synthetic
// scenes), produced from ground-truth instance maps with a documented, seeded noise model.
//
// Failure modes of real entity segmenters (CropFormer/EntitySeg, SAM) and how they are simulated,
// per view, in this order:
//   1. under-segmentation: two touching instances (sharing boundary pixels) merge into one mask;
//   2. over-segmentation: an instance is cut in two by a random line through its centroid;
//   3. misses: masks below `miss_area_fraction` of the image are dropped with `miss_probability`;
//   4. boundary jitter: each mask grows or shrinks by up to `jitter_px` pixels;
//   5. spurious masks: random ellipses on background/stuff pixels;
//   6. masks smaller than `min_area_px` are removed (CropFormer drops masks under 400 px at ~1600
//   px
//      width; we scale that to the image), and ids are shuffled per view (ids carry no meaning
//      across views).
// Level "none" keeps only step 6 (ground truth with random ids). Deterministic from the seed.
// Stateless, thread-safe.
#pragma once

#include <cstdint>
#include <string>

#include "absl/status/statusor.h"
#include "common/scene/image_io.h"

namespace instascene {

struct MaskNoiseOptions {
  float merge_probability = 0.0f;      // per touching pair of instances
  float split_probability = 0.0f;      // per instance
  float miss_probability = 0.0f;       // per small instance (below miss_area_fraction)
  float miss_area_fraction = 0.004f;   // "small" = below this fraction of the image area
  int jitter_px = 0;                   // max boundary shift, px
  float spurious_per_view = 0.0f;      // expected spurious background masks per view
  float min_area_fraction = 0.00025f;  // masks under this fraction of the image are removed
                                       // (CropFormer's 400 px at 1600x1000)

  // Presets calibrated to the failure rates reported for class-agnostic segmenters on cluttered
  // indoor scenes (docs/SYNTHETIC.md): none, low, medium, high.
  static absl::StatusOr<MaskNoiseOptions> Level(const std::string& level);
};

// Noisy per-view label map from a ground-truth instance map (0 = background / stuff).
LabelMap SimulateSegmenter(const LabelMap& gt, const MaskNoiseOptions& options, uint64_t seed);

}  // namespace instascene
