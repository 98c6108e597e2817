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

namespace {

// Per pair a < b (key a * n + b), over the frames where one of them is held and the other traced
// in kept masks but in fewer than min_tracker_gaussians Gaussians: the other's Gaussians in the
// held one's mask, and in other masks.
std::unordered_map<uint64_t, std::pair<uint32_t, uint32_t>> Glimpses(
    const TrackerSet& set, const std::vector<uint32_t>& instance_of, size_t n,
    const std::vector<std::vector<int64_t>>& holders, const DecompositionOptions& options) {
  std::unordered_map<uint64_t, std::pair<uint32_t, uint32_t>> glimpses;
  std::vector<uint32_t> total(n + 1), in_holder(n + 1);
  for (int v = 0; v < set.num_views; ++v) {
    const std::vector<uint32_t>& frame = set.view_trackers[v];
    std::fill(total.begin(), total.end(), 0u);
    for (uint32_t t : frame)
      for (uint32_t g : set.trackers[t].gaussians) ++total[instance_of[g]];
    for (size_t a = 1; a <= n; ++a) {
      const int64_t h = holders[v][a - 1];
      if (h < 0) continue;
      std::fill(in_holder.begin(), in_holder.end(), 0u);
      for (uint32_t g : set.trackers[h].gaussians) ++in_holder[instance_of[g]];
      for (size_t b = 1; b <= n; ++b) {
        if (b == a || holders[v][b - 1] >= 0 || total[b] == 0 ||
            total[b] >= static_cast<uint32_t>(options.min_tracker_gaussians))
          continue;
        const uint64_t key = uint64_t{std::min(a, b) - 1} * n + (std::max(a, b) - 1);
        glimpses[key].first += in_holder[b];
        glimpses[key].second += total[b] - in_holder[b];
      }
    }
  }
  return glimpses;
}

}  // namespace

namespace {

// Per pair a < b (key a * n + b): frames holding them together, frames holding them apart.
std::unordered_map<uint64_t, std::pair<uint32_t, uint32_t>> HoldEvidence(
    const std::vector<std::vector<int64_t>>& holders, size_t n) {
  std::unordered_map<uint64_t, std::pair<uint32_t, uint32_t>> evidence;
  for (const std::vector<int64_t>& holder : holders) {
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
  return evidence;
}

// Each set of the union becomes one instance (at its first member's place): the union of the
// Gaussians, every member's masks and coverage, the joined box.
std::vector<Instance> MergeSets(UnionFind& sets, std::vector<Instance>* instances) {
  std::vector<Instance> merged;
  const std::vector<uint32_t> component = sets.Components();
  for (uint32_t a = 0; a < instances->size(); ++a) {
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
  return merged;
}

}  // namespace

int MergeUnseparatedInstances(const TrackerSet& set, const DecompositionOptions& options,
                              std::vector<Instance>* instances) {
  const size_t n = instances->size();
  if (options.merge_min_joins <= 0 || n < 2) return 0;
  const std::vector<uint32_t> instance_of = InstanceOf(*instances, set.num_gaussians);
  const std::vector<std::vector<int64_t>> holders = HoldersPerFrame(set, instance_of, n, options);
  const auto evidence = HoldEvidence(holders, n);
  UnionFind sets(n);
  int merges = 0;
  for (const auto& [key, e] : evidence) {  // components do not depend on the visiting order
    const double j = e.first, s = e.second;
    if (j < options.merge_min_joins || s > options.merge_max_separation * (j + s)) continue;
    merges += sets.Union(static_cast<uint32_t>(key / n), static_cast<uint32_t>(key % n));
  }
  if (options.merge_glimpse_min > 0) {
    for (const auto& [key, g] : Glimpses(set, instance_of, n, holders, options)) {
      const auto held = evidence.find(key);
      if (held != evidence.end() && held->second.second > 0) continue;  // held apart somewhere
      const double in = g.first, out = g.second;
      if (in < options.merge_glimpse_min || out > options.merge_max_separation * (in + out))
        continue;
      merges += sets.Union(static_cast<uint32_t>(key / n), static_cast<uint32_t>(key % n));
    }
  }
  if (merges == 0) return 0;
  std::vector<Instance> merged = MergeSets(sets, instances);
  instances->swap(merged);
  return merges;
}

}  // namespace instascene::decomposition
