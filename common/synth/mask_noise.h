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
// Level "none" keeps only step 6 (ground truth with random ids).
//
// A second, independent family ("sam-low", "sam-medium", "sam-high") simulates a part-aware
// segmenter (SAM-style automatic masks), so that methods tuned on the first family can be reported
// on one they never saw. Per view, independently (so views disagree):
//   a. part splits: an instance is cut into 2-3 parts along its longer image axis at random
//      quantiles (caps, handles, heads), not by a line through the centroid;
//   b. merges of touching instances, and of non-touching instances of similar image area (identical
//      objects segmented as one "kind of thing");
//   c. misses of small instances;
//   d. boundary bleed: a mask grows `bleed_px` into the instance it touches (not into background);
//   e. label flicker: a few small holes punched into masks;
//   then step 6 above. Deterministic from the seed. Stateless, thread-safe.
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
  // The part-aware family ("sam-*"): when true, the steps a-e above replace steps 1-5.
  bool part_family = false;
  float part_split_probability = 0.0f;     // per instance: cut into 2-3 parts
  float similar_merge_probability = 0.0f;  // per non-touching pair of similar area (within 25 %)
  int bleed_px = 0;                        // a mask grows this far into a touching instance
  float flicker_probability = 0.0f;        // per instance: small holes punched into its mask

  // Presets calibrated to the failure rates reported for class-agnostic segmenters on cluttered
  // indoor scenes (docs/SYNTHETIC.md): none, low, medium, high; and the part-aware family
  // sam-low, sam-medium, sam-high.
  static absl::StatusOr<MaskNoiseOptions> Level(const std::string& level);
};

// Noisy per-view label map from a ground-truth instance map (0 = background / stuff).
LabelMap SimulateSegmenter(const LabelMap& gt, const MaskNoiseOptions& options, uint64_t seed);

}  // namespace instascene
