#include "services/decomposition/instance_merging.h"

#include <algorithm>
#include <unordered_map>

#include "services/decomposition/mask_holding.h"
#include "services/decomposition/union_find.h"

namespace instascene::decomposition {

int RejudgeUndersegmented(const TrackerSet& set, const std::vector<Instance>& instances,
                          const DecompositionOptions& options, std::vector<uint8_t>* undersegmented,
                          const std::vector<TrackerFrames>* frames) {
  const std::vector<uint32_t> instance_of = InstanceOf(instances, set.num_gaussians);
  int changed = 0;
  std::vector<uint32_t> counts(instances.size() + 1, 0);
  for (size_t t = 0; t < set.trackers.size(); ++t) {
    if (!(*undersegmented)[t]) continue;
    const std::vector<uint32_t>& gaussians = set.trackers[t].gaussians;
    std::fill(counts.begin(), counts.end(), 0u);
    for (uint32_t g : gaussians) ++counts[instance_of[g]];
    const uint32_t covered = static_cast<uint32_t>(gaussians.size()) - counts[0];
    // The instance holding most of the tracker (none when there are no instances).
    const auto best_it = std::max_element(counts.begin() + 1, counts.end());
    const uint32_t best = best_it == counts.end() ? 0 : *best_it;
    const bool covered_enough =
        covered > 0 && covered >= options.rejudge_min_coverage * gaussians.size();
    bool restore = covered_enough && best >= options.remedy_ratio * covered;
    if (restore && options.rejudge_remainder_max_apart < 1.0 &&
        gaussians.size() - covered >= static_cast<size_t>(options.min_tracker_gaussians)) {
      // The part outside every instance: the rest of the same object, or another object the
      // clustering never found. Masks hold an object's parts together in most frames, two
      // objects apart.
      const uint32_t b = static_cast<uint32_t>(best_it - counts.begin());
      std::vector<uint32_t> inside, outside;
      for (uint32_t g : gaussians) {
        if (instance_of[g] == b) inside.push_back(g);
        if (instance_of[g] == 0) outside.push_back(g);
      }
      const std::optional<double> apart = ShareHeldApart(set, inside, outside, options);
      if (apart && *apart > options.rejudge_remainder_max_apart) restore = false;
    }
    if (!covered_enough && frames != nullptr && options.uncovered_min_labelled <= 1.0) {
      const TrackerFrames& f = (*frames)[t];
      restore = f.visible >= options.uncovered_min_labelled * f.traced &&
                f.split <= options.uncovered_max_split * f.visible;
    }
    if (restore) {
      (*undersegmented)[t] = 0;
      ++changed;
    }
  }
  return changed;
}

int MergeUnseparatedInstances(const TrackerSet& set, const DecompositionOptions& options,
                              std::vector<Instance>* instances) {
  const size_t n = instances->size();
  if (options.merge_min_joins <= 0 || n < 2) return 0;
  const std::vector<uint32_t> instance_of = InstanceOf(*instances, set.num_gaussians);
  // Per pair a < b (key a * n + b): frames holding them together, frames holding them apart.
  std::unordered_map<uint64_t, std::pair<uint32_t, uint32_t>> evidence;
  for (const std::vector<int64_t>& holder : HoldersPerFrame(set, instance_of, n, options)) {
    std::vector<uint32_t> held;  // instances held by one mask in this frame
    for (size_t a = 0; a < n; ++a) {
      if (holder[a] >= 0) held.push_back(static_cast<uint32_t>(a));
    }
    for (size_t i = 0; i < held.size(); ++i) {
      for (size_t k = i + 1; k < held.size(); ++k) {
        const uint32_t a = held[i], b = held[k];
        auto& e = evidence[uint64_t{a} * n + b];
        (holder[a] == holder[b] ? e.first : e.second) += 1;
      }
    }
  }
  UnionFind sets(n);
  int merges = 0;
  for (const auto& [key, e] : evidence) {  // components do not depend on the visiting order
    const double j = e.first, s = e.second;
    if (j < options.merge_min_joins || s > options.merge_max_separation * (j + s)) continue;
    merges += sets.Union(static_cast<uint32_t>(key / n), static_cast<uint32_t>(key % n));
  }
  if (merges == 0) return 0;
  std::vector<Instance> merged;
  const std::vector<uint32_t> component = sets.Components();
  for (uint32_t a = 0; a < n; ++a) {
    if (component[a] == merged.size()) {  // its set's first member
      merged.push_back(std::move((*instances)[a]));
      continue;
    }
    Instance& target = merged[component[a]];
    Instance& source = (*instances)[a];
    std::vector<uint32_t> uni;
    std::set_union(target.gaussians.begin(), target.gaussians.end(), source.gaussians.begin(),
                   source.gaussians.end(), std::back_inserter(uni));
    target.gaussians.swap(uni);
    target.masks.insert(target.masks.end(), source.masks.begin(), source.masks.end());
    target.coverage.insert(target.coverage.end(), source.coverage.begin(), source.coverage.end());
    target.box.extend(source.box);
  }
  instances->swap(merged);
  return merges;
}

}  // namespace instascene::decomposition
