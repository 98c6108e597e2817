// common/synth/mask_noise_steps.h: the steps of the simulated segmenters (mask_noise.h) that
// the two noise families share, and the part-aware family (part_segmenter.cc). Internal to
// the synth library; every step draws from the caller's generator in a fixed order.
#pragma once

#include <cstdint>
#include <map>
#include <random>
#include <set>
#include <utility>

#include "common/synth/mask_noise.h"

namespace instascene::mask_noise {

float Uniform(std::mt19937_64& rng);  // in [0, 1)

// Merged instances: each merged id points at the one it joined (follow to the root).
using MergedInto = std::map<uint16_t, uint16_t>;
uint16_t RootOf(MergedInto& merged_into, uint16_t id);

// Touching pairs merged, each with probability merge_probability.
MergedInto MergeTouching(const MaskNoiseOptions& o, std::mt19937_64& rng,
                         const std::set<std::pair<uint16_t, uint16_t>>& touching);

// The last step of both families: masks below the minimum area dropped, then random ids 1..K
// (ids carry no meaning across views).
void FinishMasks(LabelMap& map, const MaskNoiseOptions& o, std::mt19937_64& rng);

// The part-aware family (steps a-e of mask_noise.h), drawn in the order b, a, c, d, e.
LabelMap SimulatePartSegmenter(const LabelMap& gt, const MaskNoiseOptions& o, std::mt19937_64& rng,
                               const std::map<uint16_t, size_t>& area,
                               const std::set<std::pair<uint16_t, uint16_t>>& touching);

}  // namespace instascene::mask_noise
