// services/decomposition/mask_graph.h: view-consensus mask clustering (ALGORITHM.md 4.2-4.6,
// adapted from MaskClustering): per-tracker visibility / containment / under-segmentation, undoing
// under-segmented masks, the observer-count schedule and the iterative graph clustering.
// Sparse throughout: visibility is a bitset over views per tracker, containment a sorted list of
// tracker ids; pairwise work only touches pairs that share a container. Deterministic; thread-safe
// (no shared state).
#pragma once

#include <cstdint>
#include <vector>

#include "services/decomposition/options.h"
#include "services/decomposition/tracker.h"

namespace instascene::decomposition {

// Bitset over views.
struct ViewSet {
  std::vector<uint64_t> words;
  explicit ViewSet(int num_views = 0) : words((num_views + 63) / 64, 0) {}
  void Set(int v) { words[v / 64] |= uint64_t{1} << (v % 64); }
  void Clear(int v) { words[v / 64] &= ~(uint64_t{1} << (v % 64)); }
  bool Test(int v) const { return (words[v / 64] >> (v % 64)) & 1; }
  int Count() const;
  int CountCommon(const ViewSet& other) const;  // |this AND other|
  void Or(const ViewSet& other);
};

// Per tracker, how the frames saw it (4.3): `traced` frames trace at least 1 -
// mask_visible_threshold of its Gaussians, `visible` frames hold that share in kept masks (the
// own frame included), `split` visible frames spread it over several masks.
struct TrackerFrames {
  uint16_t traced = 0, visible = 0, split = 0;
};

struct MaskJudgement {
  std::vector<ViewSet> visible;  // per tracker: frames where it is visible and contained
  std::vector<std::vector<uint32_t>>
      contained;                        // per tracker: trackers (masks) that contain it, sorted
  std::vector<uint8_t> undersegmented;  // per tracker
  std::vector<TrackerFrames> frames;    // per tracker
};

// 4.2-4.3: judge every tracker against every frame it could be seen in.
MaskJudgement JudgeTrackers(const TrackerSet& trackers, const DecompositionOptions& options);

// 4.4: trackers contained in an under-segmented mask U lose U's frame; U stops being a container.
void UndoUndersegmented(const TrackerSet& trackers, MaskJudgement* judgement);

// 4.5: observer thresholds, from the non-zero entries of V V^T over the given trackers (numpy
// linear-interpolation percentiles 95, 90, ..., 0; values <= 1 become 1 above the median, stop
// below).
std::vector<double> ObserverSchedule(const MaskJudgement& judgement,
                                     const std::vector<uint32_t>& nodes);

// A cluster of masks.
struct MaskNode {
  std::vector<uint32_t> masks;  // tracker ids, in merge order
  ViewSet visible;
  std::vector<uint32_t> contained;  // sorted tracker ids of containers
};

// 4.6: iterative view-consensus clustering of the non-under-segmented trackers.
std::vector<MaskNode> ClusterMasks(const TrackerSet& trackers, const MaskJudgement& judgement,
                                   const DecompositionOptions& options,
                                   std::vector<double>* schedule_out = nullptr);

}  // namespace instascene::decomposition
