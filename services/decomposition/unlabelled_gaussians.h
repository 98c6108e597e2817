// services/decomposition/unlabelled_gaussians.h: Gaussians that no instance holds after the
// clustering — untraced ones and traced orphans — joined to the instance their neighbours or masks
// point to (DECOMPOSITION.md). Deterministic for any thread count.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "common/splat/gaussian_cloud.h"
#include "services/decomposition/options.h"
#include "services/decomposition/post_process.h"
#include "services/decomposition/tracker.h"

namespace instascene::decomposition {

// Gaussians that no view traces (weight above the tracker threshold at no pixel: the surfels
// between and behind the ones carrying a view's weight) join the instance of the nearest traced
// Gaussian within `radius` (scene units), if that one is in an instance (see
// DecompositionOptions::untraced_radius). Returns how many joined an instance.
size_t LabelUntracedGaussians(const TrackerSet& trackers, const GaussianCloud& cloud, float radius,
                              int num_threads, std::vector<Instance>* instances);

// Traced Gaussians in no instance join an instance that their masks hold in at least
// orphan_min_held of the frames tracing them, grown from the instances through such Gaussians in
// steps of at most `radius` (scene units): the nearest along them when several qualify. Returns
// how many joined an instance.
size_t LabelOrphanGaussians(const TrackerSet& trackers, const GaussianCloud& cloud, float radius,
                            const DecompositionOptions& options, std::vector<Instance>* instances);

}  // namespace instascene::decomposition
