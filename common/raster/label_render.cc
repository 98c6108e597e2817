#include "common/raster/label_render.h"

#include <algorithm>
#include <utility>

#include "absl/strings/str_cat.h"
#include "common/core/status.h"
#include "common/raster/rasterizer.h"

namespace instascene {

std::vector<uint32_t> LabelMapFromTrace(const RenderResult& traced,
                                        const std::vector<uint32_t>& labels, float min_alpha) {
  std::vector<uint32_t> map(static_cast<size_t>(traced.width) * traced.height, 0);
  const ContributorTrace& trace = traced.trace;
  std::vector<std::pair<uint32_t, float>> sums;  // few labels per pixel: a flat list beats a map
  for (size_t i = 0; i < trace.num_pixels(); ++i) {
    const uint32_t pix = trace.pixels[i];
    if (traced.alpha[pix] < min_alpha) continue;
    sums.clear();
    for (uint64_t k = trace.offsets[i]; k < trace.offsets[i + 1]; ++k) {
      const uint32_t id = labels[trace.entries[k].gaussian];
      auto it =
          std::find_if(sums.begin(), sums.end(), [id](const auto& s) { return s.first == id; });
      if (it == sums.end()) {
        sums.emplace_back(id, trace.entries[k].weight);
      } else {
        it->second += trace.entries[k].weight;
      }
    }
    uint32_t best = 0;
    float best_weight = -1.0f;
    for (const auto& [id, weight] : sums) {  // first maximum: ties go to the front-most label
      if (weight > best_weight) {
        best = id;
        best_weight = weight;
      }
    }
    map[pix] = best;
  }
  return map;
}

absl::StatusOr<std::vector<uint32_t>> RenderLabelMap(const GaussianCloud& cloud,
                                                     const PinholeCamera& camera,
                                                     const std::vector<uint32_t>& labels,
                                                     float min_alpha, int num_threads) {
  if (labels.size() != cloud.size()) {
    return absl::InvalidArgumentError(absl::StrCat(
        "label count ", labels.size(), " differs from the Gaussian count ", cloud.size()));
  }
  RenderOptions options;
  options.color = false;
  options.trace.enabled = true;
  options.num_threads = num_threads;
  ASSIGN_OR_RETURN(RenderResult r, Render(cloud, camera, options));
  return LabelMapFromTrace(r, labels, min_alpha);
}

}  // namespace instascene
