// services/decomposition/mask_holding.h: which mask of a frame holds which instance — the
// per-frame evidence that the re-judgement of merged masks, the merging of unseparated instances
// and the labelling of orphan Gaussians weigh (ALGORITHM.md 4.7-4.8 and DECOMPOSITION.md).
// Deterministic; thread-safe (no shared state).
#pragma once

#include <cstddef>
#include <cstdint>
#include <optional>
#include <vector>

#include "services/decomposition/options.h"
#include "services/decomposition/post_process.h"
#include "services/decomposition/tracker.h"

namespace instascene::decomposition {

// Per Gaussian: 1 + the index of its instance, 0 in none (overlaps: the later instance).
std::vector<uint32_t> InstanceOf(const std::vector<Instance>& instances, uint32_t num_gaussians);

// Frames where masks hold the Gaussian groups `a` and `b` apart, over the frames where each is held
// (at least 1 - mask_visible_threshold of it in kept masks, one mask holding more than
// contained_threshold of that); nullopt when no frame holds both.
std::optional<double> ShareHeldApart(const TrackerSet& set, const std::vector<uint32_t>& a,
                                     const std::vector<uint32_t>& b,
                                     const DecompositionOptions& options);

// Per frame, per instance (n of them, labelled 1..n in instance_of): the tracker holding it, or -1.
// An instance is held in a frame when at least min_tracker_gaussians of its Gaussians lie in the
// frame's kept masks and one mask holds more than contained_threshold of them.
std::vector<std::vector<int64_t>> HoldersPerFrame(const TrackerSet& set,
                                                  const std::vector<uint32_t>& instance_of,
                                                  size_t n, const DecompositionOptions& options);

// Per frame v, per instance k (labelled 1..n in instance_of): missed[v * n + k - 1] = 1 when at
// least min_tracker_gaussians of its Gaussians are traced in v and more than
// mask_visible_threshold of those lie in no kept mask there (the judgement's "not visible").
std::vector<uint8_t> MissedPerFrame(const TrackerSet& set, const std::vector<uint32_t>& instance_of,
                                    size_t n, const DecompositionOptions& options);

}  // namespace instascene::decomposition
