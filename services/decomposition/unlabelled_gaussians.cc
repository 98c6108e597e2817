#include "services/decomposition/unlabelled_gaussians.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <numeric>

#include "common/core/parallel.h"
#include "common/geometry/point_index.h"
#include "services/decomposition/mask_holding.h"

namespace instascene::decomposition {
namespace {

// Adds gaussians[i] to instance joins[i] - 1 where joins[i] > 0 (gaussians ascending, in no
// instance); returns how many were added.
size_t AddToInstances(const std::vector<uint32_t>& gaussians, const std::vector<uint32_t>& joins,
                      std::vector<Instance>* instances) {
  size_t joined = 0;
  std::vector<std::vector<uint32_t>> added(instances->size());
  for (size_t i = 0; i < gaussians.size(); ++i) {
    if (joins[i] == 0) continue;
    added[joins[i] - 1].push_back(gaussians[i]);
    ++joined;
  }
  for (size_t k = 0; k < instances->size(); ++k) {
    if (added[k].empty()) continue;
    std::vector<uint32_t>& members = (*instances)[k].gaussians;
    std::vector<uint32_t> merged;
    merged.reserve(members.size() + added[k].size());
    std::merge(members.begin(), members.end(), added[k].begin(), added[k].end(),
               std::back_inserter(merged));  // both sorted and disjoint
    members.swap(merged);
  }
  return joined;
}

}  // namespace

size_t LabelUntracedGaussians(const TrackerSet& set, const GaussianCloud& cloud, float radius,
                              int num_threads, std::vector<Instance>* instances) {
  if (!(radius > 0) || instances->empty()) return 0;
  std::vector<uint32_t> instance_of(set.num_gaussians, 0);  // overlaps: the later instance
  for (size_t k = 0; k < instances->size(); ++k) {
    for (uint32_t g : (*instances)[k].gaussians) instance_of[g] = static_cast<uint32_t>(k + 1);
  }
  std::vector<uint32_t> traced, untraced;
  std::vector<Eigen::Vector3f> traced_points;
  for (uint32_t g = 0; g < set.num_gaussians; ++g) {
    const uint16_t* frames = nullptr;
    if (set.FramesOf(g, &frames) > 0) {
      traced.push_back(g);
      traced_points.emplace_back(&cloud.positions[3 * g]);
    } else if (instance_of[g] == 0) {
      untraced.push_back(g);
    }
  }
  if (traced.empty() || untraced.empty()) return 0;
  const PointIndex3 index(std::move(traced_points));
  std::vector<uint32_t> joins(untraced.size(), 0);
  const float radius2 = radius * radius;
  RunWithThreads(num_threads, [&] {
    tbb::parallel_for(size_t{0}, untraced.size(), [&](size_t i) {
      const auto [nearest, d2] = index.Nearest(Eigen::Vector3f(&cloud.positions[3 * untraced[i]]));
      if (d2 <= radius2) joins[i] = instance_of[traced[nearest]];
    });
  });
  return AddToInstances(untraced, joins, instances);
}

namespace {

// Per tracker: the instances (ids from 1) it holds.
std::vector<std::vector<uint32_t>> InstancesHeldByTracker(const TrackerSet& set,
                                                          const std::vector<uint32_t>& label,
                                                          size_t n,
                                                          const DecompositionOptions& options) {
  std::vector<std::vector<uint32_t>> held_by(set.trackers.size());
  for (const std::vector<int64_t>& holder : HoldersPerFrame(set, label, n, options)) {
    for (size_t a = 0; a < n; ++a) {
      if (holder[a] >= 0) held_by[holder[a]].push_back(static_cast<uint32_t>(a + 1));
    }
  }
  return held_by;
}

// Per orphan: the instances its masks hold in at least min_held of its frames (those where the
// instance was not missed: missed[v * n + k - 1]), sorted.
std::vector<std::vector<uint32_t>> AllowedInstances(
    const TrackerSet& set, const std::vector<uint32_t>& orphans,
    const std::vector<std::vector<uint32_t>>& held_by, const std::vector<uint8_t>& missed, size_t n,
    const DecompositionOptions& options) {
  std::vector<std::vector<uint32_t>> allowed(orphans.size());
  RunWithThreads(options.num_threads, [&] {
    tbb::parallel_for(size_t{0}, orphans.size(), [&](size_t i) {
      const uint32_t g = orphans[i];
      std::map<uint32_t, uint32_t> votes;  // label -> frames whose mask holds that instance
      for (uint64_t m = set.mask_offsets[g]; m < set.mask_offsets[g + 1]; ++m) {
        const size_t row = size_t(set.trackers[set.masks[m]].view) * n;
        for (uint32_t k : held_by[set.masks[m]]) votes[k] += missed[row + k - 1] == 0;
      }
      const uint16_t* frames = nullptr;
      const size_t traced = set.FramesOf(g, &frames);
      for (const auto& [k, count] : votes) {
        size_t counted = 0;  // traced frames where instance k was not missed
        for (size_t f = 0; f < traced; ++f) counted += missed[size_t(frames[f]) * n + k - 1] == 0;
        if (count > 0 && count >= options.orphan_min_held * counted) allowed[i].push_back(k);
      }
    });
  });
  return allowed;
}

// Each pending orphan's neighbours within `radius` among the labelled Gaussians and the pending
// orphans, nearest first (at most 16), found once.
std::vector<std::vector<uint32_t>> NeighboursWithinStep(const GaussianCloud& cloud,
                                                        const std::vector<uint32_t>& label,
                                                        const std::vector<uint32_t>& pending,
                                                        float radius, int num_threads) {
  std::vector<uint32_t> domain;
  for (uint32_t g = 0; g < label.size(); ++g) {
    if (label[g] > 0) domain.push_back(g);
  }
  domain.insert(domain.end(), pending.begin(), pending.end());
  std::vector<Eigen::Vector3f> points;
  points.reserve(domain.size());
  for (uint32_t g : domain) points.emplace_back(&cloud.positions[3 * g]);
  const PointIndex3 index(std::move(points));
  constexpr size_t kNeighbours = 16;
  const float radius2 = radius * radius;
  std::vector<std::vector<uint32_t>> near(pending.size());
  RunWithThreads(num_threads, [&] {
    tbb::parallel_for(size_t{0}, pending.size(), [&](size_t j) {
      const Eigen::Vector3f p(&cloud.positions[3 * pending[j]]);
      for (const auto& [q, d2] : index.KNearest(p, kNeighbours)) {
        if (d2 > radius2) break;
        near[j].push_back(domain[q]);
      }
    });
  });
  return near;
}

// Grows the instances through the orphans in steps: each round, a pending orphan joins the first
// allowed instance among its step neighbours' labels (visible to the next round only). Returns
// each orphan's instance (0: none).
std::vector<uint32_t> GrowThroughOrphans(const std::vector<uint32_t>& orphans,
                                         const std::vector<std::vector<uint32_t>>& allowed,
                                         std::vector<uint32_t> pending,
                                         const std::vector<std::vector<uint32_t>>& near,
                                         const DecompositionOptions& options,
                                         std::vector<uint32_t>* label) {
  std::vector<uint32_t> joins(orphans.size(), 0);
  std::vector<uint32_t> order(pending.size());  // position in `near` of each pending orphan
  std::iota(order.begin(), order.end(), 0u);
  while (!pending.empty() && !IsCancelled(options.cancel)) {  // Decompose reports the cancel
    std::vector<uint32_t> found(pending.size(), 0);
    RunWithThreads(options.num_threads, [&] {
      tbb::parallel_for(size_t{0}, pending.size(), [&](size_t j) {
        const std::vector<uint32_t>& allow = allowed[pending[j]];
        for (uint32_t q : near[order[j]]) {
          const uint32_t l = (*label)[q];
          if (l > 0 && std::binary_search(allow.begin(), allow.end(), l)) {
            found[j] = l;
            break;
          }
        }
      });
    });
    std::vector<uint32_t> still, still_order;
    for (size_t j = 0; j < pending.size(); ++j) {
      if (found[j] == 0) {
        still.push_back(pending[j]);
        still_order.push_back(order[j]);
        continue;
      }
      joins[pending[j]] = found[j];
      (*label)[orphans[pending[j]]] = found[j];
    }
    if (still.size() == pending.size()) break;
    pending.swap(still);
    order.swap(still_order);
  }
  return joins;
}

}  // namespace

size_t LabelOrphanGaussians(const TrackerSet& set, const GaussianCloud& cloud, float radius,
                            const DecompositionOptions& options, std::vector<Instance>* instances) {
  const size_t n = instances->size();
  if (!(options.orphan_min_held <= 1.0) || !(radius > 0) || n == 0) return 0;
  std::vector<uint32_t> label = InstanceOf(*instances, set.num_gaussians);
  const std::vector<std::vector<uint32_t>> held_by = InstancesHeldByTracker(set, label, n, options);
  // Per frame v and instance k: missed[v * n + k - 1] when the segmenter missed it there.
  const std::vector<uint8_t> missed = options.orphan_skips_missed_frames
                                          ? MissedPerFrame(set, label, n, options)
                                          : std::vector<uint8_t>(size_t(set.num_views) * n, 0);
  // Orphans: traced, in no instance.
  std::vector<uint32_t> orphans;
  for (uint32_t g = 0; g < set.num_gaussians; ++g) {
    if (label[g] == 0 && set.frame_offsets[g + 1] > set.frame_offsets[g]) orphans.push_back(g);
  }
  const std::vector<std::vector<uint32_t>> allowed =
      AllowedInstances(set, orphans, held_by, missed, n, options);
  // Grow the instances through their orphans in steps of at most `radius`, so that an orphan
  // joins the allowed instance nearest along the orphans, not across a gap to a neighbour.
  std::vector<uint32_t> pending, pending_gaussians;
  for (size_t i = 0; i < orphans.size(); ++i) {
    if (allowed[i].empty()) continue;
    pending.push_back(static_cast<uint32_t>(i));
    pending_gaussians.push_back(orphans[i]);
  }
  if (pending.empty()) return 0;
  const std::vector<std::vector<uint32_t>> near =
      NeighboursWithinStep(cloud, label, pending_gaussians, radius, options.num_threads);
  const std::vector<uint32_t> joins =
      GrowThroughOrphans(orphans, allowed, std::move(pending), near, options, &label);
  return AddToInstances(orphans, joins, instances);
}

}  // namespace instascene::decomposition
