#include "services/decomposition/mask_holding.h"

#include <algorithm>
#include <unordered_map>

namespace instascene::decomposition {

std::vector<uint32_t> InstanceOf(const std::vector<Instance>& instances, uint32_t num_gaussians) {
  std::vector<uint32_t> instance_of(num_gaussians, 0);
  for (size_t k = 0; k < instances.size(); ++k) {
    for (uint32_t g : instances[k].gaussians) instance_of[g] = static_cast<uint32_t>(k + 1);
  }
  return instance_of;
}

std::optional<double> ShareHeldApart(const TrackerSet& set, const std::vector<uint32_t>& a,
                                     const std::vector<uint32_t>& b,
                                     const DecompositionOptions& options) {
  // Per frame, per group: the holding tracker, or -1 when the group is not held there.
  auto holders = [&](const std::vector<uint32_t>& group) {
    std::unordered_map<uint32_t, uint32_t> counts;  // tracker -> members of the group
    for (uint32_t g : group) {
      for (uint64_t k = set.mask_offsets[g]; k < set.mask_offsets[g + 1]; ++k)
        ++counts[set.masks[k]];
    }
    std::vector<uint32_t> total(set.num_views, 0), top(set.num_views, 0);
    std::vector<int64_t> holder(set.num_views, -1);
    for (const auto& [u, c] : counts) {
      const int v = set.trackers[u].view;
      total[v] += c;
      if (c > top[v] || (c == top[v] && static_cast<int64_t>(u) < holder[v])) {
        top[v] = c;
        holder[v] = u;
      }
    }
    const double size = static_cast<double>(group.size());
    for (int v = 0; v < set.num_views; ++v) {
      if ((size - total[v]) / size > options.mask_visible_threshold ||
          !(top[v] > options.contained_threshold * total[v])) {
        holder[v] = -1;
      }
    }
    return holder;
  };
  const std::vector<int64_t> ha = holders(a), hb = holders(b);
  int together = 0, apart = 0;
  for (int v = 0; v < set.num_views; ++v) {
    if (ha[v] < 0 || hb[v] < 0) continue;
    (ha[v] == hb[v] ? together : apart) += 1;
  }
  if (together + apart == 0) return std::nullopt;
  return static_cast<double>(apart) / (together + apart);
}

std::vector<std::vector<int64_t>> HoldersPerFrame(const TrackerSet& set,
                                                  const std::vector<uint32_t>& instance_of,
                                                  size_t n, const DecompositionOptions& options) {
  std::vector<std::vector<int64_t>> holders(set.num_views, std::vector<int64_t>(n, -1));
  std::vector<uint32_t> counts, total(n + 1), best(n + 1);
  for (int v = 0; v < set.num_views; ++v) {
    const std::vector<uint32_t>& frame = set.view_trackers[v];
    if (frame.empty()) continue;
    counts.assign(frame.size() * (n + 1), 0);
    for (size_t i = 0; i < frame.size(); ++i) {
      for (uint32_t g : set.trackers[frame[i]].gaussians) ++counts[i * (n + 1) + instance_of[g]];
    }
    std::fill(total.begin(), total.end(), 0u);
    std::fill(best.begin(), best.end(), 0u);
    std::vector<int64_t>& holder = holders[v];
    for (size_t i = 0; i < frame.size(); ++i) {
      for (size_t a = 1; a <= n; ++a) {
        const uint32_t c = counts[i * (n + 1) + a];
        total[a] += c;
        if (c > best[a]) {
          best[a] = c;
          holder[a - 1] = frame[i];
        }
      }
    }
    for (size_t a = 1; a <= n; ++a) {
      if (total[a] < static_cast<uint32_t>(options.min_tracker_gaussians) ||
          !(best[a] > options.contained_threshold * total[a])) {
        holder[a - 1] = -1;
      }
    }
  }
  return holders;
}

std::vector<uint8_t> MissedPerFrame(const TrackerSet& set, const std::vector<uint32_t>& instance_of,
                                    size_t n, const DecompositionOptions& options) {
  const size_t cells = size_t(set.num_views) * n;
  std::vector<uint32_t> traced(cells, 0), masked(cells, 0);
  for (uint32_t g = 0; g < set.num_gaussians; ++g) {
    const uint32_t k = instance_of[g];
    if (k == 0) continue;
    const uint16_t* frames = nullptr;
    const size_t count = set.FramesOf(g, &frames);
    for (size_t f = 0; f < count; ++f) ++traced[size_t(frames[f]) * n + k - 1];
    for (uint64_t m = set.mask_offsets[g]; m < set.mask_offsets[g + 1]; ++m) {
      ++masked[size_t(set.trackers[set.masks[m]].view) * n + k - 1];
    }
  }
  std::vector<uint8_t> missed(cells, 0);
  for (size_t c = 0; c < cells; ++c) {
    missed[c] =
        traced[c] >= static_cast<uint32_t>(options.min_tracker_gaussians) &&
        traced[c] - std::min(masked[c], traced[c]) > options.mask_visible_threshold * traced[c];
  }
  return missed;
}

}  // namespace instascene::decomposition
