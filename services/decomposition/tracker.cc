#include "services/decomposition/tracker.h"

#include <algorithm>

#include "absl/strings/str_cat.h"
#include "common/core/status.h"
#include "common/raster/rasterizer.h"

namespace instascene::decomposition {

absl::Status DecompositionOptions::Validate() const {
  auto in01 = [](double v) { return v >= 0.0 && v <= 1.0; };
  if (!in01(mask_visible_threshold) || !in01(contained_threshold) || !in01(undersegment_threshold) ||
      !in01(view_consensus_threshold) || !in01(point_filter_threshold) || !in01(overlap_ratio) || !in01(remedy_ratio)) {
    return absl::InvalidArgumentError("decomposition thresholds must lie in [0, 1]");
  }
  if (!(tracker_min_weight >= 0.0f && tracker_min_weight < 1.0f)) {
    return absl::InvalidArgumentError("tracker_min_weight must lie in [0, 1)");
  }
  if (min_tracker_gaussians < 1) return absl::InvalidArgumentError("min_tracker_gaussians must be >= 1");
  if (!(dbscan_eps > 0.0) || dbscan_min_points < 1) {
    return absl::InvalidArgumentError("dbscan_eps must be > 0 and dbscan_min_points >= 1");
  }
  return absl::OkStatus();
}

absl::StatusOr<TrackerSet> BuildTrackers(const GaussianCloud& cloud, const std::vector<PinholeCamera>& cameras,
                                         const MaskLoader& load_mask, const DecompositionOptions& options,
                                         const std::function<void(int, int)>& progress) {
  RETURN_IF_ERROR(options.Validate());
  if (cameras.size() > 65535) return absl::InvalidArgumentError("at most 65535 views");
  TrackerSet set;
  set.num_views = static_cast<int>(cameras.size());
  set.num_gaussians = cloud.size();
  set.view_trackers.resize(cameras.size());
  // Per view: traced Gaussians, and (Gaussian, tracker) of kept masks, highest mask id last.
  std::vector<std::vector<uint32_t>> frame_gaussians(cameras.size());
  std::vector<std::vector<std::pair<uint32_t, uint32_t>>> gaussian_masks(cameras.size());
  RasterWorkspace workspace;
  RenderResult render;
  RenderOptions render_options;
  render_options.color = false;
  render_options.trace.enabled = true;
  render_options.trace.min_weight =
      options.tracker_rule == TrackerRule::kWeight ? options.tracker_min_weight : 0.0f;
  render_options.num_threads = options.num_threads;
  render_options.workspace = &workspace;
  std::vector<std::pair<uint32_t, uint32_t>> pairs;  // (mask label, Gaussian)
  for (size_t v = 0; v < cameras.size(); ++v) {
    ASSIGN_OR_RETURN(std::vector<uint32_t> labels, load_mask(static_cast<int>(v)));
    if (labels.size() != static_cast<size_t>(cameras[v].width) * cameras[v].height) {
      return absl::InvalidArgumentError(absl::StrCat("mask of view ", v, " has ", labels.size(),
                                                     " pixels, its camera ", cameras[v].width, "x", cameras[v].height));
    }
    RETURN_IF_ERROR(RenderInto(cloud, cameras[v], render_options, &render));
    const ContributorTrace& trace = render.trace;
    pairs.clear();
    std::vector<uint32_t>& traced = frame_gaussians[v];
    traced.clear();
    for (size_t i = 0; i < trace.num_pixels(); ++i) {
      const uint32_t label = labels[trace.pixels[i]];
      for (uint64_t k = trace.offsets[i]; k < trace.offsets[i + 1]; ++k) {
        const Contribution& c = trace.entries[k];
        if (options.tracker_rule == TrackerRule::kMedianCrossing &&
            !(c.transmittance > 0.5f && c.transmittance - c.weight < 0.5f)) {
          continue;
        }
        traced.push_back(c.gaussian);
        if (label != 0) pairs.emplace_back(label, c.gaussian);
      }
    }
    std::sort(traced.begin(), traced.end());
    traced.erase(std::unique(traced.begin(), traced.end()), traced.end());
    std::sort(pairs.begin(), pairs.end());
    pairs.erase(std::unique(pairs.begin(), pairs.end()), pairs.end());
    for (size_t b = 0; b < pairs.size();) {
      size_t e = b;
      while (e < pairs.size() && pairs[e].first == pairs[b].first) ++e;
      if (e - b >= static_cast<size_t>(options.min_tracker_gaussians)) {
        Tracker t;
        t.view = static_cast<int>(v);
        t.mask_id = pairs[b].first;
        for (size_t k = b; k < e; ++k) t.gaussians.push_back(pairs[k].second);
        const uint32_t index = static_cast<uint32_t>(set.trackers.size());
        for (uint32_t g : t.gaussians) gaussian_masks[v].emplace_back(g, index);
        set.view_trackers[v].push_back(index);
        set.trackers.push_back(std::move(t));
      }
      b = e;
    }
    // One mask per Gaussian and frame: the highest mask id (visited last) wins.
    auto& gm = gaussian_masks[v];
    std::stable_sort(gm.begin(), gm.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
    size_t out = 0;
    for (size_t k = 0; k < gm.size(); ++k) {
      if (k + 1 < gm.size() && gm[k + 1].first == gm[k].first) continue;
      gm[out++] = gm[k];
    }
    gm.resize(out);
    if (progress) progress(static_cast<int>(v) + 1, static_cast<int>(cameras.size()));
  }
  // Per-Gaussian CSR indices.
  const size_t n = cloud.size();
  set.frame_offsets.assign(n + 1, 0);
  set.mask_offsets.assign(n + 1, 0);
  for (size_t v = 0; v < cameras.size(); ++v) {
    for (uint32_t g : frame_gaussians[v]) ++set.frame_offsets[g + 1];
    for (const auto& [g, t] : gaussian_masks[v]) ++set.mask_offsets[g + 1];
  }
  for (size_t g = 0; g < n; ++g) {
    set.frame_offsets[g + 1] += set.frame_offsets[g];
    set.mask_offsets[g + 1] += set.mask_offsets[g];
  }
  set.frames.resize(set.frame_offsets[n]);
  set.masks.resize(set.mask_offsets[n]);
  std::vector<uint64_t> frame_cursor(set.frame_offsets.begin(), set.frame_offsets.end() - 1);
  std::vector<uint64_t> mask_cursor(set.mask_offsets.begin(), set.mask_offsets.end() - 1);
  for (size_t v = 0; v < cameras.size(); ++v) {  // views ascending: each list is sorted by frame
    for (uint32_t g : frame_gaussians[v]) set.frames[frame_cursor[g]++] = static_cast<uint16_t>(v);
    for (const auto& [g, t] : gaussian_masks[v]) set.masks[mask_cursor[g]++] = t;
    std::vector<uint32_t>().swap(frame_gaussians[v]);
    std::vector<std::pair<uint32_t, uint32_t>>().swap(gaussian_masks[v]);
  }
  return set;
}

}  // namespace instascene::decomposition
