// services/decomposition/testing/hand_trackers.h: hand-built tracker sets and clouds for the
// decomposition's unit tests (masks as Gaussian ranges or lists, every Gaussian traced in every
// view), and the clustering steps run with given under-segmentation flags.
#pragma once

#include <cstdint>
#include <vector>

#include "common/splat/gaussian_cloud.h"
#include "services/decomposition/decompose.h"
#include "services/decomposition/mask_graph.h"

namespace instascene::decomposition {

// A mask given as (view, mask id, Gaussian range [lo, hi)).
struct HandMask {
  int view;
  uint32_t id;
  uint32_t lo, hi;
};

struct ListMask {
  int view;
  uint32_t id;
  std::vector<uint32_t> gaussians;  // sorted
};

// Every Gaussian is traced in every view; it belongs to the masks that list it.
TrackerSet MakeSetFromLists(int num_views, uint32_t num_gaussians,
                            const std::vector<ListMask>& masks);

std::vector<uint32_t> Range(uint32_t lo, uint32_t hi);  // lo, lo + 1, ..., hi - 1

TrackerSet MakeSet(int num_views, uint32_t num_gaussians, const std::vector<HandMask>& masks);

// Gaussians on the x axis, 1 mm apart (one DBSCAN cluster); those from `far_from` on are moved
// 5 units away (a second cluster).
GaussianCloud LineCloud(int n, int far_from);

// Steps 3-6 with the given under-segmentation flags: undo, cluster, build instances.
std::vector<Instance> InstancesWithFlags(const TrackerSet& set, const MaskJudgement& judged,
                                         const std::vector<uint8_t>& flags,
                                         const GaussianCloud& cloud,
                                         const DecompositionOptions& options);

}  // namespace instascene::decomposition
