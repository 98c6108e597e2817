// services/decomposition/tracker.h: spatial Gaussian trackers (paper 3.2, ALGORITHM.md 4.1).
//
// For every view, the scene is rendered with contributor tracing and each 2D mask collects the
// Gaussians traced into its pixels; masks with fewer than min_tracker_gaussians Gaussians are
// dropped. Everything is stored sparsely: per tracker its sorted Gaussian ids, per Gaussian the
// frames it is traced in and the kept masks it belongs to (the highest mask id per frame, as the
// released code's last write wins). Memory is O(traced (Gaussian, frame) pairs), never
// Gaussians x frames or masks x masks.
#pragma once

#include <cstdint>
#include <functional>
#include <vector>

#include "absl/status/statusor.h"
#include "common/geometry/camera.h"
#include "common/splat/gaussian_cloud.h"
#include "services/decomposition/options.h"

namespace instascene::decomposition {

struct Tracker {
  int view = 0;                     // frame index
  uint32_t mask_id = 0;             // label value in that frame's mask map
  std::vector<uint32_t> gaussians;  // sorted, unique
};

struct TrackerSet {
  int num_views = 0;
  size_t num_gaussians = 0;
  std::vector<Tracker> trackers;  // global mask index = position; views ascending, then mask ids
  std::vector<std::vector<uint32_t>> view_trackers;  // per view: its tracker indices
  // Per Gaussian g: frames it is traced in: frames[frame_offsets[g] .. frame_offsets[g + 1]).
  std::vector<uint64_t> frame_offsets;
  std::vector<uint16_t> frames;
  // Per Gaussian g: the tracker it belongs to in each frame where it lies in a kept mask.
  std::vector<uint64_t> mask_offsets;
  std::vector<uint32_t> masks;

  size_t FramesOf(uint32_t g, const uint16_t** begin) const {
    *begin = frames.data() + frame_offsets[g];
    return frame_offsets[g + 1] - frame_offsets[g];
  }
};

// Supplies the label map of view v (W*H ids, 0 = none) when the tracker needs it.
using MaskLoader = std::function<absl::StatusOr<std::vector<uint32_t>>(int view)>;

absl::StatusOr<TrackerSet> BuildTrackers(
    const GaussianCloud& cloud, const std::vector<PinholeCamera>& cameras,
    const MaskLoader& load_mask, const DecompositionOptions& options,
    const std::function<void(int done, int total)>& progress = nullptr);

}  // namespace instascene::decomposition
