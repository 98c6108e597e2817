#include "services/training/vote.h"

#include <filesystem>

#include "absl/strings/str_cat.h"
#include "common/core/status.h"
#include "common/raster/rasterizer.h"
#include "common/scene/image_io.h"

namespace instascene::training {

absl::StatusOr<std::vector<uint32_t>> VoteLabels(const Scene& scene, const GaussianCloud& cloud,
                                                 const std::string& decomposition_dir,
                                                 int num_threads) {
  // Per Gaussian a short list of (label, summed weight): a Gaussian sees few instances.
  std::vector<std::vector<std::pair<uint32_t, float>>> votes(cloud.size());
  RenderOptions options;
  options.color = false;
  options.trace.enabled = true;
  options.num_threads = num_threads;
  RasterWorkspace workspace;
  options.workspace = &workspace;
  RenderResult render;
  for (const SceneView& view : scene.views) {
    ASSIGN_OR_RETURN(LabelMap sorted, ReadLabelMap((std::filesystem::path(decomposition_dir) /
                                                    "masks_sorted" / (view.name + ".png"))
                                                       .string()));
    if (sorted.width != view.camera.width || sorted.height != view.camera.height) {
      return absl::InvalidArgumentError(
          absl::StrCat("masks_sorted of view '", view.name, "' does not match its camera"));
    }
    RETURN_IF_ERROR(RenderInto(cloud, view.camera, options, &render));
    const ContributorTrace& trace = render.trace;
    for (size_t i = 0; i < trace.num_pixels(); ++i) {
      const uint32_t label = sorted.labels[trace.pixels[i]];
      for (uint64_t k = trace.offsets[i]; k < trace.offsets[i + 1]; ++k) {
        auto& list = votes[trace.entries[k].gaussian];
        auto it = std::find_if(list.begin(), list.end(),
                               [label](const auto& v) { return v.first == label; });
        if (it == list.end()) {
          list.emplace_back(label, trace.entries[k].weight);
        } else {
          it->second += trace.entries[k].weight;
        }
      }
    }
  }
  std::vector<uint32_t> labels(cloud.size(), 0);
  for (size_t g = 0; g < cloud.size(); ++g) {
    float best = 0.0f;
    for (const auto& [label, weight] : votes[g]) {
      if (weight > best) {
        best = weight;
        labels[g] = label;
      }
    }
  }
  return labels;
}

}  // namespace instascene::training
