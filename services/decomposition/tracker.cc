#include "services/decomposition/tracker.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <mutex>

#include "absl/strings/str_cat.h"
#include "common/core/parallel.h"
#include "common/core/status.h"
#include "common/raster/rasterizer.h"

namespace instascene::decomposition {

namespace {

// What one view contributes, computed independently of the others.
struct ViewTrackers {
  std::vector<Tracker> trackers;
  std::vector<uint32_t> traced;  // sorted unique Gaussians
  std::vector<std::pair<uint32_t, uint32_t>>
      gaussian_mask;  // (Gaussian, local tracker), one per Gaussian
};

// The view's traced (mask label, Gaussian) pairs, sorted and unique, and its traced Gaussians:
// every contribution above the tracker weight, or with the median rule those where the
// transmittance crosses 0.5.
void TracedPairs(const ContributorTrace& trace, const std::vector<uint32_t>& labels,
                 const DecompositionOptions& options, size_t num_gaussians,
                 std::vector<std::pair<uint32_t, uint32_t>>* pairs, std::vector<uint32_t>* traced) {
  std::vector<uint8_t> seen(num_gaussians, 0);  // cheaper than sorting every traced entry
  for (size_t i = 0; i < trace.num_pixels(); ++i) {
    const uint32_t label = labels[trace.pixels[i]];
    for (uint64_t k = trace.offsets[i]; k < trace.offsets[i + 1]; ++k) {
      const Contribution& c = trace.entries[k];
      if (options.tracker_rule == TrackerRule::kMedianCrossing &&
          !(trace.transmittance[k] > 0.5f && trace.transmittance[k] - c.weight < 0.5f)) {
        continue;
      }
      seen[c.gaussian] = 1;
      if (label != 0) pairs->emplace_back(label, c.gaussian);
    }
  }
  for (uint32_t g = 0; g < seen.size(); ++g) {
    if (seen[g]) traced->push_back(g);
  }
  std::sort(pairs->begin(), pairs->end());
  pairs->erase(std::unique(pairs->begin(), pairs->end()), pairs->end());
}

// One tracker per mask holding at least min_tracker_gaussians; one mask per Gaussian and frame
// (the highest mask id, visited last, wins).
void MakeTrackers(const std::vector<std::pair<uint32_t, uint32_t>>& pairs, int view,
                  int min_tracker_gaussians, ViewTrackers* out) {
  for (size_t b = 0; b < pairs.size();) {
    size_t e = b;
    while (e < pairs.size() && pairs[e].first == pairs[b].first) ++e;
    if (e - b >= static_cast<size_t>(min_tracker_gaussians)) {
      Tracker t;
      t.view = view;
      t.mask_id = pairs[b].first;
      for (size_t k = b; k < e; ++k) t.gaussians.push_back(pairs[k].second);
      const uint32_t local = static_cast<uint32_t>(out->trackers.size());
      for (uint32_t g : t.gaussians) out->gaussian_mask.emplace_back(g, local);
      out->trackers.push_back(std::move(t));
    }
    b = e;
  }
  auto& gm = out->gaussian_mask;
  std::stable_sort(gm.begin(), gm.end(),
                   [](const auto& a, const auto& b) { return a.first < b.first; });
  size_t kept = 0;
  for (size_t k = 0; k < gm.size(); ++k) {
    if (k + 1 < gm.size() && gm[k + 1].first == gm[k].first) continue;
    gm[kept++] = gm[k];
  }
  gm.resize(kept);
}

absl::StatusOr<ViewTrackers> TrackView(const GaussianCloud& cloud, const PinholeCamera& camera,
                                       int view, const MaskLoader& load_mask,
                                       const DecompositionOptions& options) {
  ASSIGN_OR_RETURN(std::vector<uint32_t> labels, load_mask(view));
  if (labels.size() != static_cast<size_t>(camera.width) * camera.height) {
    return absl::InvalidArgumentError(absl::StrCat("mask of view ", view, " has ", labels.size(),
                                                   " pixels, its camera ", camera.width, "x",
                                                   camera.height));
  }
  RenderOptions render_options;
  render_options.color = false;
  render_options.trace.enabled = true;
  render_options.trace.min_weight =
      options.tracker_rule == TrackerRule::kWeight ? options.tracker_min_weight : 0.0f;
  render_options.trace.transmittance = options.tracker_rule == TrackerRule::kMedianCrossing;
  ASSIGN_OR_RETURN(RenderResult render, Render(cloud, camera, render_options));
  ViewTrackers out;
  std::vector<std::pair<uint32_t, uint32_t>> pairs;  // (mask label, Gaussian)
  TracedPairs(render.trace, labels, options, cloud.size(), &pairs, &out.traced);
  MakeTrackers(pairs, view, options.min_tracker_gaussians, &out);
  return out;
}

// The views' trackers numbered in view order, and the per-Gaussian CSR indices of the frames
// that trace each Gaussian and of the masks that hold it.
TrackerSet AssembleTrackers(std::vector<absl::StatusOr<ViewTrackers>>& views, size_t n) {
  const int num_views = static_cast<int>(views.size());
  TrackerSet set;
  set.num_views = num_views;
  set.num_gaussians = n;
  set.view_trackers.resize(views.size());
  std::vector<uint32_t> first_tracker(views.size());
  for (int v = 0; v < num_views; ++v) {
    first_tracker[v] = static_cast<uint32_t>(set.trackers.size());
    for (Tracker& t : views[v]->trackers) {
      set.view_trackers[v].push_back(static_cast<uint32_t>(set.trackers.size()));
      set.trackers.push_back(std::move(t));
    }
  }
  set.frame_offsets.assign(n + 1, 0);
  set.mask_offsets.assign(n + 1, 0);
  for (int v = 0; v < num_views; ++v) {
    for (uint32_t g : views[v]->traced) ++set.frame_offsets[g + 1];
    for (const auto& [g, t] : views[v]->gaussian_mask) ++set.mask_offsets[g + 1];
  }
  for (size_t g = 0; g < n; ++g) {
    set.frame_offsets[g + 1] += set.frame_offsets[g];
    set.mask_offsets[g + 1] += set.mask_offsets[g];
  }
  set.frames.resize(set.frame_offsets[n]);
  set.masks.resize(set.mask_offsets[n]);
  std::vector<uint64_t> frame_cursor(set.frame_offsets.begin(), set.frame_offsets.end() - 1);
  std::vector<uint64_t> mask_cursor(set.mask_offsets.begin(), set.mask_offsets.end() - 1);
  for (int v = 0; v < num_views; ++v) {  // views ascending: each list is sorted by frame
    for (uint32_t g : views[v]->traced) set.frames[frame_cursor[g]++] = static_cast<uint16_t>(v);
    for (const auto& [g, t] : views[v]->gaussian_mask)
      set.masks[mask_cursor[g]++] = first_tracker[v] + t;
    views[v] = ViewTrackers{};  // release memory early
  }
  return set;
}

}  // namespace

absl::StatusOr<TrackerSet> BuildTrackers(const GaussianCloud& cloud,
                                         const std::vector<PinholeCamera>& cameras,
                                         const MaskLoader& load_mask,
                                         const DecompositionOptions& options,
                                         const std::function<void(int, int)>& progress) {
  RETURN_IF_ERROR(options.Validate());
  if (cameras.size() > 65535) return absl::InvalidArgumentError("at most 65535 views");
  const int num_views = static_cast<int>(cameras.size());
  // Views are independent: trace them in parallel (each render is itself tile-parallel), then
  // number the trackers in view order so the result does not depend on scheduling.
  std::vector<absl::StatusOr<ViewTrackers>> views(cameras.size(), absl::UnknownError("not run"));
  std::mutex progress_mutex;
  int done = 0;
  RunWithThreads(options.num_threads, [&] {
    tbb::parallel_for(0, num_views, [&](int v) {
      if (IsCancelled(options.cancel)) {
        views[v] = absl::CancelledError("tracking: cancelled");
        return;
      }
      views[v] = TrackView(cloud, cameras[v], v, load_mask, options);
      if (progress) {
        std::lock_guard<std::mutex> lock(progress_mutex);
        progress(++done, num_views);
      }
    });
  });
  for (const absl::StatusOr<ViewTrackers>& v : views) RETURN_IF_ERROR(v.status());
  return AssembleTrackers(views, cloud.size());
}

}  // namespace instascene::decomposition
