// services/decomposition/instance_merging.h: instances the clustering left apart joined again, and
// masks wrongly judged merges re-judged, by how the frames' masks hold them (ALGORITHM.md 4.8 and
// DECOMPOSITION.md). Deterministic; thread-safe (no shared state).
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "services/decomposition/mask_graph.h"
#include "services/decomposition/options.h"
#include "services/decomposition/post_process.h"
#include "services/decomposition/tracker.h"

namespace instascene::decomposition {

// Re-judgement: clears the under-segmented flag of every flagged tracker whose Gaussians lie
// mostly in one instance (see DecompositionOptions::rejudge_passes) and, given the judgement's
// per-tracker frame counts, of every flagged tracker mostly outside all instances that the
// masks hold consistently and split rarely (DecompositionOptions::uncovered_min_labelled);
// returns how many changed.
int RejudgeUndersegmented(const TrackerSet& trackers, const std::vector<Instance>& instances,
                          const DecompositionOptions& options, std::vector<uint8_t>* undersegmented,
                          const std::vector<TrackerFrames>* frames = nullptr);

// Merging of unseparated instances: per frame, an instance is held by a mask when at least
// min_tracker_gaussians of its Gaussians lie in the frame's masks and one mask holds more than
// contained_threshold of them. Pairs held by one mask count a join, by two masks a separation;
// pairs with >= merge_min_joins joins and separations <= merge_max_separation of their frames
// merge (transitively). Returns the number of merges.
int MergeUnseparatedInstances(const TrackerSet& trackers, const DecompositionOptions& options,
                              std::vector<Instance>* instances);

}  // namespace instascene::decomposition
