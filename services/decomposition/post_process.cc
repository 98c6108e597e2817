#include "services/decomposition/post_process.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <numeric>
#include <optional>
#include <unordered_map>

#include "common/core/parallel.h"
#include "common/geometry/point_index.h"
#include "services/decomposition/union_find.h"

namespace instascene::decomposition {
namespace {

size_t IntersectionSize(const std::vector<uint32_t>& a, const std::vector<uint32_t>& b) {
  size_t i = 0, k = 0, n = 0;
  while (i < a.size() && k < b.size()) {
    if (a[i] < b[k]) {
      ++i;
    } else if (b[k] < a[i]) {
      ++k;
    } else {
      ++n;
      ++i;
      ++k;
    }
  }
  return n;
}

// Sub-objects of one node (4.7 steps 1-2).
std::vector<Instance> SplitNode(const TrackerSet& set, const MaskNode& node,
                                const GaussianCloud& cloud, const DecompositionOptions& options,
                                float eps, const std::vector<uint8_t>* undersegmented) {
  std::vector<Instance> out;
  if (node.masks.size() < 2) return out;
  // The node's Gaussians: the union of its trackers.
  std::vector<uint32_t> points;
  for (uint32_t t : node.masks)
    points.insert(points.end(), set.trackers[t].gaussians.begin(), set.trackers[t].gaussians.end());
  std::sort(points.begin(), points.end());
  points.erase(std::unique(points.begin(), points.end()), points.end());
  std::vector<Eigen::Vector3f> xyz(points.size());
  for (size_t i = 0; i < points.size(); ++i)
    xyz[i] = Eigen::Vector3f(&cloud.positions[3 * points[i]]);
  const std::vector<int> cluster = Dbscan(xyz, eps, options.dbscan_min_points);
  const int num_groups =
      1 + *std::max_element(cluster.begin(), cluster.end()) + 1;  // noise is group 0
  // Detection ratio over the node's visible frames.
  std::vector<uint16_t> appear(points.size(), 0), detected(points.size(), 0);
  // A frame where the point lies in a mask judged under-segmented (a merge of this object with
  // its neighbour) says nothing about the point's object and does not count against it
  // (DecompositionOptions::filter_skips_merged_frames).
  const bool skip_merged = options.filter_skips_merged_frames && undersegmented != nullptr;
  for (size_t i = 0; i < points.size(); ++i) {
    const uint16_t* frames = nullptr;
    const size_t count = set.FramesOf(points[i], &frames);
    for (size_t k = 0; k < count; ++k) appear[i] += node.visible.Test(frames[k]);
    if (!skip_merged) continue;
    const uint32_t g = points[i];
    for (uint64_t m = set.mask_offsets[g]; m < set.mask_offsets[g + 1]; ++m) {
      const uint32_t t = set.masks[m];
      if ((*undersegmented)[t] && node.visible.Test(set.trackers[t].view) && appear[i] > 0)
        --appear[i];
    }
  }
  std::vector<uint32_t> masks_by_view = node.masks;
  std::stable_sort(masks_by_view.begin(), masks_by_view.end(), [&](uint32_t a, uint32_t b) {
    return set.trackers[a].view < set.trackers[b].view;
  });
  std::vector<int> last_frame(points.size(), -1);
  for (uint32_t t : masks_by_view) {
    const Tracker& tracker = set.trackers[t];
    if (!node.visible.Test(tracker.view)) continue;
    size_t i = 0;
    for (uint32_t g : tracker.gaussians) {  // both sorted: merge walk
      while (i < points.size() && points[i] < g) ++i;
      if (i < points.size() && points[i] == g && last_frame[i] != tracker.view) {
        last_frame[i] = tracker.view;
        ++detected[i];
      }
    }
  }
  for (int group = 0; group < num_groups; ++group) {
    Instance sub;
    for (size_t i = 0; i < points.size(); ++i) {
      if (cluster[i] + 1 != group) continue;
      sub.box.extend(xyz[i]);
      if (detected[i] / (appear[i] + 1e-6) > options.point_filter_threshold)
        sub.gaussians.push_back(points[i]);
    }
    if (sub.gaussians.empty()) continue;
    out.push_back(std::move(sub));
  }
  // Each mask goes to the sub-object it overlaps most.
  for (uint32_t t : node.masks) {
    size_t best = 0, best_overlap = 0;
    for (size_t s = 0; s < out.size(); ++s) {
      const size_t overlap = IntersectionSize(set.trackers[t].gaussians, out[s].gaussians);
      if (overlap > best_overlap) {
        best_overlap = overlap;
        best = s;
      }
    }
    if (best_overlap == 0) continue;
    out[best].masks.push_back(t);
    out[best].coverage.push_back(static_cast<float>(best_overlap) / out[best].gaussians.size());
  }
  out.erase(
      std::remove_if(out.begin(), out.end(), [](const Instance& s) { return s.masks.size() < 2; }),
      out.end());
  return out;
}

}  // namespace

std::vector<int> Dbscan(const std::vector<Eigen::Vector3f>& points, float eps, int min_points) {
  // Grid DBSCAN: cells of side eps / sqrt(3), so any two points of one cell are neighbours. A cell
  // with >= min_points points makes all its points core without any query; other points count
  // neighbours in the 5x5x5 surrounding cells with an early exit. Core cells are joined when some
  // pair of their core points is within eps; border points take the cluster of their nearest core
  // point. The core-point clusters are exactly DBSCAN's (border points, which DBSCAN assigns by
  // visiting order, may differ).
  const size_t n = points.size();
  std::vector<int> label(n, -1);
  if (n == 0) return label;
  const float cell = eps / std::sqrt(3.0f), eps2 = eps * eps;
  auto key_of = [&](const Eigen::Vector3f& p) {
    return Eigen::Vector3i(static_cast<int>(std::floor(p.x() / cell)),
                           static_cast<int>(std::floor(p.y() / cell)),
                           static_cast<int>(std::floor(p.z() / cell)));
  };
  struct KeyHash {
    size_t operator()(const Eigen::Vector3i& k) const {
      return static_cast<size_t>(k.x()) * 73856093u ^ static_cast<size_t>(k.y()) * 19349663u ^
             static_cast<size_t>(k.z()) * 83492791u;
    }
  };
  std::unordered_map<Eigen::Vector3i, uint32_t, KeyHash> cell_of_key;
  std::vector<std::vector<uint32_t>> cells;  // point indices, ascending
  std::vector<Eigen::Vector3i> keys;
  std::vector<uint32_t> cell_of(n);
  for (uint32_t i = 0; i < n; ++i) {
    const Eigen::Vector3i k = key_of(points[i]);
    auto [it, inserted] = cell_of_key.try_emplace(k, static_cast<uint32_t>(cells.size()));
    if (inserted) {
      cells.emplace_back();
      keys.push_back(k);
    }
    cells[it->second].push_back(i);
    cell_of[i] = it->second;
  }
  auto for_each_neighbour_cell = [&](uint32_t c, auto&& fn) {
    for (int dx = -2; dx <= 2; ++dx) {
      for (int dy = -2; dy <= 2; ++dy) {
        for (int dz = -2; dz <= 2; ++dz) {
          auto it = cell_of_key.find(keys[c] + Eigen::Vector3i(dx, dy, dz));
          if (it != cell_of_key.end() && !fn(it->second)) return;
        }
      }
    }
  };
  std::vector<uint8_t> core(n, 0);
  for (uint32_t c = 0; c < cells.size(); ++c) {
    if (static_cast<int>(cells[c].size()) >= min_points) {
      for (uint32_t i : cells[c]) core[i] = 1;
      continue;
    }
    for (uint32_t i : cells[c]) {
      int count = 0;
      for_each_neighbour_cell(c, [&](uint32_t d) {
        for (uint32_t j : cells[d]) count += (points[i] - points[j]).squaredNorm() <= eps2;
        return count < min_points;
      });
      core[i] = count >= min_points;
    }
  }
  // Union core cells that have a core pair within eps.
  UnionFind sets(cells.size());
  std::vector<std::vector<uint32_t>> core_points(cells.size());
  for (uint32_t c = 0; c < cells.size(); ++c) {
    for (uint32_t i : cells[c]) {
      if (core[i]) core_points[c].push_back(i);
    }
  }
  for (uint32_t c = 0; c < cells.size(); ++c) {
    if (core_points[c].empty()) continue;
    for_each_neighbour_cell(c, [&](uint32_t d) {
      if (d <= c || core_points[d].empty() || sets.Find(c) == sets.Find(d)) return true;
      for (uint32_t i : core_points[c]) {
        for (uint32_t j : core_points[d]) {
          if ((points[i] - points[j]).squaredNorm() <= eps2) {
            sets.Union(c, d);
            return true;
          }
        }
      }
      return true;
    });
  }
  // Number clusters by their first core point in index order.
  std::vector<int> cluster_of_root(cells.size(), -1);
  int next = 0;
  for (uint32_t i = 0; i < n; ++i) {
    if (!core[i]) continue;
    const uint32_t root = sets.Find(cell_of[i]);
    if (cluster_of_root[root] < 0) cluster_of_root[root] = next++;
    label[i] = cluster_of_root[root];
  }
  for (uint32_t i = 0; i < n; ++i) {  // border points: the nearest core point within eps
    if (core[i]) continue;
    float best = eps2;
    int best_label = -1;
    for_each_neighbour_cell(cell_of[i], [&](uint32_t d) {
      for (uint32_t j : core_points[d]) {
        const float d2 = (points[i] - points[j]).squaredNorm();
        if (d2 <= best && (best_label < 0 || d2 < best)) {
          best = d2;
          best_label = label[j];
        }
      }
      return true;
    });
    label[i] = best_label;
  }
  return label;
}

float RobustSceneDiagonal(const GaussianCloud& cloud) {
  return cloud.size() == 0 ? 0.0f : RobustBounds(cloud).diagonal().norm();
}

std::vector<Instance> BuildInstances(const TrackerSet& set, const std::vector<MaskNode>& nodes,
                                     const GaussianCloud& cloud,
                                     const DecompositionOptions& options,
                                     const std::vector<uint8_t>* undersegmented) {
  const float eps = static_cast<float>(options.dbscan_eps_relative
                                           ? options.dbscan_eps * RobustSceneDiagonal(cloud)
                                           : options.dbscan_eps);
  std::vector<std::vector<Instance>> per_node(nodes.size());
  RunWithThreads(options.num_threads, [&] {
    tbb::parallel_for(size_t{0}, nodes.size(), [&](size_t k) {
      per_node[k] = SplitNode(set, nodes[k], cloud, options, eps, undersegmented);
    });
  });
  std::vector<Instance> objects;
  for (auto& list : per_node) {
    for (Instance& s : list) objects.push_back(std::move(s));
  }
  // Remove contained duplicates (the dropped object's masks are not transferred).
  std::vector<uint8_t> dropped(objects.size(), 0);
  for (size_t a = 0; a < objects.size(); ++a) {
    for (size_t b = a + 1; b < objects.size() && !dropped[a]; ++b) {
      if (dropped[b] || !objects[a].box.intersects(objects[b].box)) continue;
      const double inter =
          static_cast<double>(IntersectionSize(objects[a].gaussians, objects[b].gaussians));
      if (inter / objects[a].gaussians.size() > options.overlap_ratio) {
        dropped[a] = 1;
      } else if (inter / objects[b].gaussians.size() > options.overlap_ratio) {
        dropped[b] = 1;
      }
    }
  }
  std::vector<Instance> kept;
  for (size_t a = 0; a < objects.size(); ++a) {
    if (!dropped[a]) kept.push_back(std::move(objects[a]));
  }
  return kept;
}

namespace {

// Frames where masks hold the Gaussian groups `a` and `b` apart, over the frames where each is held
// (at least 1 - mask_visible_threshold of it in kept masks, one mask holding more than
// contained_threshold of that); nullopt when no frame holds both.
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

}  // namespace

int RejudgeUndersegmented(const TrackerSet& set, const std::vector<Instance>& instances,
                          const DecompositionOptions& options, std::vector<uint8_t>* undersegmented,
                          const std::vector<TrackerFrames>* frames) {
  std::vector<uint32_t> instance_of(set.num_gaussians, 0);  // overlaps: the later instance
  for (size_t k = 0; k < instances.size(); ++k) {
    for (uint32_t g : instances[k].gaussians) instance_of[g] = static_cast<uint32_t>(k + 1);
  }
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

// Per frame, per instance (n of them, labelled 1..n in instance_of): the tracker holding it, or -1.
// An instance is held in a frame when at least min_tracker_gaussians of its Gaussians lie in the
// frame's kept masks and one mask holds more than contained_threshold of them.
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

// Per frame v, per instance k (labelled 1..n in instance_of): missed[v * n + k - 1] = 1 when at
// least min_tracker_gaussians of its Gaussians are traced in v and more than
// mask_visible_threshold of those lie in no kept mask there (the judgement's "not visible").
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

}  // namespace

int MergeUnseparatedInstances(const TrackerSet& set, const DecompositionOptions& options,
                              std::vector<Instance>* instances) {
  const size_t n = instances->size();
  if (options.merge_min_joins <= 0 || n < 2) return 0;
  std::vector<uint32_t> instance_of(set.num_gaussians, 0);  // overlaps: the later instance
  for (size_t k = 0; k < n; ++k) {
    for (uint32_t g : (*instances)[k].gaussians) instance_of[g] = static_cast<uint32_t>(k + 1);
  }
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
  std::vector<int64_t> slot(n, -1);
  for (uint32_t a = 0; a < n; ++a) {
    const uint32_t root = sets.Find(a);
    if (slot[root] < 0) {
      slot[root] = static_cast<int64_t>(merged.size());
      merged.push_back(std::move((*instances)[a]));
      continue;
    }
    Instance& target = merged[slot[root]];
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

size_t LabelOrphanGaussians(const TrackerSet& set, const GaussianCloud& cloud, float radius,
                            const DecompositionOptions& options, std::vector<Instance>* instances) {
  const double min_held = options.orphan_min_held;
  const size_t n = instances->size();
  if (!(min_held <= 1.0) || !(radius > 0) || n == 0) return 0;
  std::vector<uint32_t> label(set.num_gaussians, 0);  // overlaps: the later instance
  for (size_t k = 0; k < n; ++k) {
    for (uint32_t g : (*instances)[k].gaussians) label[g] = static_cast<uint32_t>(k + 1);
  }
  // Per tracker: the instances it holds.
  std::vector<std::vector<uint32_t>> held_by(set.trackers.size());
  for (const std::vector<int64_t>& holder : HoldersPerFrame(set, label, n, options)) {
    for (size_t a = 0; a < n; ++a) {
      if (holder[a] >= 0) held_by[holder[a]].push_back(static_cast<uint32_t>(a + 1));
    }
  }
  // Per frame v and instance k: missed[v * n + k - 1] when the segmenter missed it there.
  const std::vector<uint8_t> missed = options.orphan_skips_missed_frames
                                          ? MissedPerFrame(set, label, n, options)
                                          : std::vector<uint8_t>(size_t(set.num_views) * n, 0);
  // Per orphan (traced, in no instance): the instances its masks hold in enough of its frames
  // (those where the instance was not missed).
  std::vector<uint32_t> orphans;
  for (uint32_t g = 0; g < set.num_gaussians; ++g) {
    if (label[g] == 0 && set.frame_offsets[g + 1] > set.frame_offsets[g]) orphans.push_back(g);
  }
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
        if (count > 0 && count >= min_held * counted) allowed[i].push_back(k);
      }
    });
  });
  // Grow the instances through their orphans in steps of at most `radius`, so that an orphan
  // joins the allowed instance nearest along the orphans, not across a gap to a neighbour.
  std::vector<uint32_t> pending, domain;
  for (size_t i = 0; i < orphans.size(); ++i) {
    if (!allowed[i].empty()) pending.push_back(static_cast<uint32_t>(i));
  }
  if (pending.empty()) return 0;
  std::vector<Eigen::Vector3f> points;
  for (uint32_t g = 0; g < set.num_gaussians; ++g) {
    if (label[g] > 0) domain.push_back(g);
  }
  for (uint32_t i : pending) domain.push_back(orphans[i]);
  for (uint32_t g : domain) points.emplace_back(&cloud.positions[3 * g]);
  const PointIndex3 index(std::move(points));
  // Each pending orphan's neighbours within one step, nearest first, found once.
  constexpr size_t kNeighbours = 16;
  const float radius2 = radius * radius;
  std::vector<std::vector<uint32_t>> near(pending.size());
  RunWithThreads(options.num_threads, [&] {
    tbb::parallel_for(size_t{0}, pending.size(), [&](size_t j) {
      const Eigen::Vector3f p(&cloud.positions[3 * orphans[pending[j]]]);
      for (const auto& [q, d2] : index.KNearest(p, kNeighbours)) {
        if (d2 > radius2) break;
        near[j].push_back(domain[q]);
      }
    });
  });
  std::vector<uint32_t> joins(orphans.size(), 0);
  std::vector<uint32_t> order(pending.size());  // position in `near` of each pending orphan
  std::iota(order.begin(), order.end(), 0u);
  while (!pending.empty() && !IsCancelled(options.cancel)) {  // Decompose reports the cancel
    std::vector<uint32_t> found(pending.size(), 0);
    RunWithThreads(options.num_threads, [&] {
      tbb::parallel_for(size_t{0}, pending.size(), [&](size_t j) {
        const std::vector<uint32_t>& allow = allowed[pending[j]];
        for (uint32_t q : near[order[j]]) {
          const uint32_t l = label[q];
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
      label[orphans[pending[j]]] = found[j];  // visible to the next step only
    }
    if (still.size() == pending.size()) break;
    pending.swap(still);
    order.swap(still_order);
  }
  return AddToInstances(orphans, joins, instances);
}

std::vector<uint32_t> RemedyUndersegmented(const TrackerSet& set, const MaskJudgement& judgement,
                                           const DecompositionOptions& options,
                                           std::vector<Instance>* instances) {
  std::vector<uint32_t> remaining;
  for (uint32_t u = 0; u < set.trackers.size(); ++u) {
    if (!judgement.undersegmented[u]) continue;
    const std::vector<uint32_t>& p = set.trackers[u].gaussians;
    size_t best = 0, best_overlap = 0;
    for (size_t k = 0; k < instances->size(); ++k) {
      const size_t overlap = IntersectionSize((*instances)[k].gaussians, p);
      if (overlap > best_overlap) {
        best_overlap = overlap;
        best = k;
      }
    }
    if (best_overlap > options.remedy_ratio * p.size()) {
      (*instances)[best].masks.push_back(u);
      (*instances)[best].coverage.push_back(1.0f);
    } else {
      remaining.push_back(u);
    }
  }
  return remaining;
}

}  // namespace instascene::decomposition
