#include "services/decomposition/testing/hand_trackers.h"

#include <numeric>

#include "services/decomposition/post_process.h"

namespace instascene::decomposition {

TrackerSet MakeSetFromLists(int num_views, uint32_t num_gaussians,
                            const std::vector<ListMask>& masks) {
  TrackerSet set;
  set.num_views = num_views;
  set.num_gaussians = num_gaussians;
  set.view_trackers.resize(num_views);
  std::vector<std::vector<uint32_t>> owner(num_gaussians);
  for (const ListMask& m : masks) {
    const uint32_t index = static_cast<uint32_t>(set.trackers.size());
    set.view_trackers[m.view].push_back(index);
    set.trackers.push_back(Tracker{m.view, m.id, m.gaussians});
    for (uint32_t g : m.gaussians) owner[g].push_back(index);
  }
  set.frame_offsets.push_back(0);
  set.mask_offsets.push_back(0);
  for (uint32_t g = 0; g < num_gaussians; ++g) {
    for (int v = 0; v < num_views; ++v) set.frames.push_back(static_cast<uint16_t>(v));
    set.masks.insert(set.masks.end(), owner[g].begin(), owner[g].end());
    set.frame_offsets.push_back(set.frames.size());
    set.mask_offsets.push_back(set.masks.size());
  }
  return set;
}

std::vector<uint32_t> Range(uint32_t lo, uint32_t hi) {
  std::vector<uint32_t> r(hi - lo);
  std::iota(r.begin(), r.end(), lo);
  return r;
}

TrackerSet MakeSet(int num_views, uint32_t num_gaussians, const std::vector<HandMask>& masks) {
  std::vector<ListMask> lists;
  for (const HandMask& m : masks) lists.push_back({m.view, m.id, Range(m.lo, m.hi)});
  return MakeSetFromLists(num_views, num_gaussians, lists);
}

GaussianCloud LineCloud(int n, int far_from) {
  GaussianCloud cloud;
  cloud.Resize(n);
  for (int g = 0; g < n; ++g) {
    cloud.positions[3 * g] = 0.001f * g + (g >= far_from ? 5.0f : 0.0f);
    cloud.positions[3 * g + 1] = cloud.positions[3 * g + 2] = 0.0f;
  }
  return cloud;
}

std::vector<Instance> InstancesWithFlags(const TrackerSet& set, const MaskJudgement& judged,
                                         const std::vector<uint8_t>& flags,
                                         const GaussianCloud& cloud,
                                         const DecompositionOptions& options) {
  MaskJudgement j = judged;
  j.undersegmented = flags;
  UndoUndersegmented(set, &j);
  return BuildInstances(set, ClusterMasks(set, j, options), cloud, options);
}

}  // namespace instascene::decomposition
