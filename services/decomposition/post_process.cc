#include "services/decomposition/post_process.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <numeric>

#include "common/core/parallel.h"
#include "common/geometry/point_index.h"
#include "services/decomposition/dbscan.h"
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

// The node's Gaussians: the union of its trackers, sorted.
std::vector<uint32_t> NodeGaussians(const TrackerSet& set, const MaskNode& node) {
  std::vector<uint32_t> points;
  for (uint32_t t : node.masks)
    points.insert(points.end(), set.trackers[t].gaussians.begin(), set.trackers[t].gaussians.end());
  std::sort(points.begin(), points.end());
  points.erase(std::unique(points.begin(), points.end()), points.end());
  return points;
}

// Per point: the node's visible frames that trace it. A frame where the point lies in a mask
// judged under-segmented (a merge of this object with its neighbour) says nothing about the
// point's object and does not count against it (DecompositionOptions::filter_skips_merged_frames).
std::vector<uint16_t> AppearCounts(const TrackerSet& set, const MaskNode& node,
                                   const std::vector<uint32_t>& points, bool skip_merged,
                                   const std::vector<uint8_t>* undersegmented) {
  std::vector<uint16_t> appear(points.size(), 0);
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
  return appear;
}

// Per point: the node's visible frames whose mask of the node holds it.
std::vector<uint16_t> DetectedCounts(const TrackerSet& set, const MaskNode& node,
                                     const std::vector<uint32_t>& points) {
  std::vector<uint16_t> detected(points.size(), 0);
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
  return detected;
}

// Each mask goes to the sub-object it overlaps most; sub-objects with fewer than 2 masks go.
void AssignMasks(const TrackerSet& set, const MaskNode& node, std::vector<Instance>* out) {
  for (uint32_t t : node.masks) {
    size_t best = 0, best_overlap = 0;
    for (size_t s = 0; s < out->size(); ++s) {
      const size_t overlap = IntersectionSize(set.trackers[t].gaussians, (*out)[s].gaussians);
      if (overlap > best_overlap) {
        best_overlap = overlap;
        best = s;
      }
    }
    if (best_overlap == 0) continue;
    (*out)[best].masks.push_back(t);
    (*out)[best].coverage.push_back(static_cast<float>(best_overlap) /
                                    (*out)[best].gaussians.size());
  }
  std::erase_if(*out, [](const Instance& s) { return s.masks.size() < 2; });
}

// Sub-objects of one node (4.7 steps 1-2): DBSCAN groups of its Gaussians, each keeping the
// points its masks detect in more than point_filter_threshold of the frames that show them.
std::vector<Instance> SplitNode(const TrackerSet& set, const MaskNode& node,
                                const GaussianCloud& cloud, const DecompositionOptions& options,
                                float eps, const std::vector<uint8_t>* undersegmented) {
  std::vector<Instance> out;
  if (node.masks.size() < 2) return out;
  const std::vector<uint32_t> points = NodeGaussians(set, node);
  std::vector<Eigen::Vector3f> xyz(points.size());
  for (size_t i = 0; i < points.size(); ++i)
    xyz[i] = Eigen::Vector3f(&cloud.positions[3 * points[i]]);
  const std::vector<int> cluster = Dbscan(xyz, eps, options.dbscan_min_points);
  const int num_groups =
      1 + *std::max_element(cluster.begin(), cluster.end()) + 1;  // noise is group 0
  const bool skip_merged = options.filter_skips_merged_frames && undersegmented != nullptr;
  const std::vector<uint16_t> appear = AppearCounts(set, node, points, skip_merged, undersegmented);
  const std::vector<uint16_t> detected = DetectedCounts(set, node, points);
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
  AssignMasks(set, node, &out);
  return out;
}

}  // namespace

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
