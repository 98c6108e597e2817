#include "services/decomposition/mask_graph.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <numeric>

#include "common/core/parallel.h"
#include "services/decomposition/union_find.h"

namespace instascene::decomposition {

int ViewSet::Count() const {
  int c = 0;
  for (uint64_t w : words) c += std::popcount(w);
  return c;
}

int ViewSet::CountCommon(const ViewSet& other) const {
  int c = 0;
  for (size_t i = 0; i < words.size(); ++i) c += std::popcount(words[i] & other.words[i]);
  return c;
}

void ViewSet::Or(const ViewSet& other) {
  for (size_t i = 0; i < words.size(); ++i) words[i] |= other.words[i];
}

namespace {

// One thread's buffers for JudgeOne, zeroed between trackers.
struct JudgeScratch {
  std::vector<uint32_t> counts;   // per container tracker: members of P labelled with it
  std::vector<uint32_t> touched;  // the trackers with a count
  std::vector<uint32_t> traced;   // per frame: members of P traced
};

// The frames where at least 1 - mask_visible_threshold of the tracker's Gaussians are traced.
int CountTracedFrames(const TrackerSet& set, const Tracker& tracker,
                      const DecompositionOptions& options, std::vector<uint32_t>* traced) {
  const double size = static_cast<double>(tracker.gaussians.size());
  for (uint32_t g : tracker.gaussians) {
    const uint16_t* frames;
    const size_t count = set.FramesOf(g, &frames);
    for (size_t q = 0; q < count; ++q) ++(*traced)[frames[q]];
  }
  int traced_num = 0;
  for (uint32_t& c : *traced) {
    traced_num += (size - static_cast<double>(c)) / size <= options.mask_visible_threshold;
    c = 0;
  }
  return traced_num;
}

// ALGORITHM.md 4.3 for tracker t: per frame where enough of its Gaussians lie in masks, whether
// one mask contains it (visible, contained) or several split it; under-segmented when split in
// more than undersegment_threshold of the frames where it is visible.
void JudgeOne(const TrackerSet& set, const DecompositionOptions& options, size_t t, JudgeScratch* s,
              MaskJudgement* j) {
  const Tracker& tracker = set.trackers[t];
  std::vector<uint32_t>& counts = s->counts;
  std::vector<uint32_t>& touched = s->touched;
  touched.clear();
  for (uint32_t g : tracker.gaussians) {
    for (uint64_t k = set.mask_offsets[g]; k < set.mask_offsets[g + 1]; ++k) {
      const uint32_t u = set.masks[k];
      if (counts[u]++ == 0) touched.push_back(u);
    }
  }
  // Trackers are ordered by view, so sorting groups the touched masks frame by frame.
  std::sort(touched.begin(), touched.end());
  const double size = static_cast<double>(tracker.gaussians.size());
  int visible_num = 0, split_num = 0;
  for (size_t b = 0; b < touched.size();) {
    const int view = set.trackers[touched[b]].view;
    size_t e = b;
    uint64_t nonzero = 0;
    uint32_t best = touched[b];
    for (; e < touched.size() && set.trackers[touched[e]].view == view; ++e) {
      nonzero += counts[touched[e]];
      if (counts[touched[e]] > counts[best]) best = touched[e];
    }
    if (view == tracker.view) {  // the own frame always counts: P is contained in itself
      ++visible_num;
      j->visible[t].Set(view);
      j->contained[t].push_back(static_cast<uint32_t>(t));
    } else if ((size - static_cast<double>(nonzero)) / size <= options.mask_visible_threshold) {
      ++visible_num;
      if (counts[best] / static_cast<double>(nonzero) > options.contained_threshold) {
        j->visible[t].Set(view);
        j->contained[t].push_back(best);
      } else {
        ++split_num;
      }
    }
    b = e;
  }
  const int traced_num = CountTracedFrames(set, tracker, options, &s->traced);
  j->frames[t] = {static_cast<uint16_t>(traced_num), static_cast<uint16_t>(visible_num),
                  static_cast<uint16_t>(split_num)};
  if (visible_num == 0 ||
      split_num / static_cast<double>(visible_num) > options.undersegment_threshold) {
    j->undersegmented[t] = 1;
  }
  std::sort(j->contained[t].begin(), j->contained[t].end());
  for (uint32_t u : touched) counts[u] = 0;
}

}  // namespace

MaskJudgement JudgeTrackers(const TrackerSet& set, const DecompositionOptions& options) {
  const size_t m = set.trackers.size();
  MaskJudgement j;
  j.visible.assign(m, ViewSet(set.num_views));
  j.contained.assign(m, {});
  j.undersegmented.assign(m, 0);
  j.frames.assign(m, {});
  RunWithThreads(options.num_threads, [&] {
    tbb::parallel_for(
        tbb::blocked_range<size_t>(0, m, 16), [&](const tbb::blocked_range<size_t>& range) {
          JudgeScratch scratch{
              std::vector<uint32_t>(m, 0), {}, std::vector<uint32_t>(set.num_views, 0)};
          for (size_t t = range.begin(); t < range.end(); ++t)
            JudgeOne(set, options, t, &scratch, &j);
        });
  });
  return j;
}

void UndoUndersegmented(const TrackerSet& set, MaskJudgement* j) {
  for (size_t t = 0; t < j->contained.size(); ++t) {
    std::vector<uint32_t>& c = j->contained[t];
    size_t out = 0;
    for (uint32_t u : c) {
      if (j->undersegmented[u]) {
        j->visible[t].Clear(set.trackers[u].view);
      } else {
        c[out++] = u;
      }
    }
    c.resize(out);
  }
}

std::vector<double> ObserverSchedule(const MaskJudgement& j, const std::vector<uint32_t>& nodes) {
  // Histogram of the non-zero entries of V V^T (both triangles and the diagonal, like the
  // flattened matrix in MaskClustering).
  std::vector<uint64_t> histogram;
  for (size_t a = 0; a < nodes.size(); ++a) {
    for (size_t b = a; b < nodes.size(); ++b) {
      const int common = j.visible[nodes[a]].CountCommon(j.visible[nodes[b]]);
      if (common == 0) continue;
      if (histogram.size() <= static_cast<size_t>(common)) histogram.resize(common + 1, 0);
      histogram[common] += a == b ? 1 : 2;
    }
  }
  uint64_t total = 0;
  for (uint64_t c : histogram) total += c;
  std::vector<double> schedule;
  if (total == 0) return schedule;
  // k-th smallest entry (0-based) from the histogram.
  auto kth = [&](uint64_t k) {
    uint64_t seen = 0;
    for (size_t v = 0; v < histogram.size(); ++v) {
      seen += histogram[v];
      if (k < seen) return static_cast<double>(v);
    }
    return static_cast<double>(histogram.size() - 1);
  };
  for (int percentile = 95; percentile >= 0; percentile -= 5) {
    const double position = percentile / 100.0 * static_cast<double>(total - 1);
    const uint64_t lo = static_cast<uint64_t>(std::floor(position));
    const double frac = position - static_cast<double>(lo);
    const double lo_value = kth(lo);
    double value = lo_value + (lo + 1 < total ? frac * (kth(lo + 1) - lo_value) : 0.0);
    if (value <= 1.0) {
      if (percentile < 50) break;
      value = 1.0;
    }
    schedule.push_back(value);
  }
  return schedule;
}

namespace {

// Each node's partners b > a: pairs sharing a container with supporter / observer >= the view
// consensus and observer >= `threshold`. Each node finds its partners independently.
std::vector<std::vector<uint32_t>> ConsensusPartners(const TrackerSet& set,
                                                     const std::vector<MaskNode>& nodes,
                                                     double threshold,
                                                     const DecompositionOptions& options) {
  const size_t n = nodes.size();
  // Inverted index: container mask -> nodes it contains.
  std::vector<std::vector<uint32_t>> by_container(set.trackers.size());
  for (uint32_t a = 0; a < n; ++a) {
    for (uint32_t c : nodes[a].contained) by_container[c].push_back(a);
  }
  std::vector<std::vector<uint32_t>> partners(n);
  RunWithThreads(options.num_threads, [&] {
    tbb::parallel_for(tbb::blocked_range<uint32_t>(0, static_cast<uint32_t>(n), 64),
                      [&](const tbb::blocked_range<uint32_t>& r) {
                        std::vector<uint32_t> support(n, 0), touched;
                        for (uint32_t a = r.begin(); a < r.end(); ++a) {
                          touched.clear();
                          for (uint32_t c : nodes[a].contained) {
                            for (uint32_t b : by_container[c]) {
                              if (b <= a) continue;
                              if (support[b]++ == 0) touched.push_back(b);
                            }
                          }
                          std::sort(touched.begin(), touched.end());
                          for (uint32_t b : touched) {
                            const double observer = nodes[a].visible.CountCommon(nodes[b].visible);
                            const double rate = support[b] / (observer + 1e-7);
                            if (rate >= options.view_consensus_threshold && observer >= threshold)
                              partners[a].push_back(b);
                            support[b] = 0;
                          }
                        }
                      });
  });
  return partners;
}

// The connected components of the partner graph (union-find, serial), each one node: masks
// concatenated, visible frames and containers united.
std::vector<MaskNode> MergePartners(const TrackerSet& set, const std::vector<MaskNode>& nodes,
                                    const std::vector<std::vector<uint32_t>>& partners) {
  const size_t n = nodes.size();
  UnionFind sets(n);
  for (uint32_t a = 0; a < n; ++a) {
    for (uint32_t b : partners[a]) sets.Union(a, b);
  }
  std::vector<MaskNode> merged;
  const std::vector<uint32_t> component = sets.Components();
  for (uint32_t a = 0; a < n; ++a) {
    if (component[a] == merged.size()) merged.push_back({{}, ViewSet(set.num_views), {}});
    MaskNode& target = merged[component[a]];
    target.masks.insert(target.masks.end(), nodes[a].masks.begin(), nodes[a].masks.end());
    target.visible.Or(nodes[a].visible);
    std::vector<uint32_t> uni;
    std::set_union(target.contained.begin(), target.contained.end(), nodes[a].contained.begin(),
                   nodes[a].contained.end(), std::back_inserter(uni));
    target.contained.swap(uni);
  }
  return merged;
}

}  // namespace

std::vector<MaskNode> ClusterMasks(const TrackerSet& set, const MaskJudgement& j,
                                   const DecompositionOptions& options,
                                   std::vector<double>* schedule_out) {
  std::vector<uint32_t> initial;
  for (uint32_t t = 0; t < set.trackers.size(); ++t) {
    if (!j.undersegmented[t]) initial.push_back(t);
  }
  std::vector<MaskNode> nodes;
  nodes.reserve(initial.size());
  for (uint32_t t : initial) nodes.push_back({{t}, j.visible[t], j.contained[t]});
  std::vector<double> schedule = ObserverSchedule(j, initial);
  if (options.observer_floor > 1 && !schedule.empty() && schedule.back() > options.observer_floor)
    schedule.push_back(options.observer_floor);
  if (schedule_out) *schedule_out = schedule;
  for (double threshold : schedule) {
    nodes = MergePartners(set, nodes, ConsensusPartners(set, nodes, threshold, options));
  }
  return nodes;
}

}  // namespace instascene::decomposition
