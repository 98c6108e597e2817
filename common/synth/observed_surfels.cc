#include "common/synth/observed_surfels.h"

#include <vector>

#include "common/core/status.h"
#include "common/raster/rasterizer.h"

namespace instascene {

absl::Status DropUnseenSurfels(ClutterScene* scene, float min_weight, int num_threads) {
  std::vector<uint8_t> seen(scene->cloud.size(), 0);
  RenderOptions options;
  options.color = false;
  options.trace.enabled = true;
  options.trace.min_weight = min_weight;
  options.num_threads = num_threads;
  for (const PinholeCamera& camera : scene->cameras) {
    ASSIGN_OR_RETURN(RenderResult render, Render(scene->cloud, camera, options));
    for (const Contribution& c : render.trace.entries) seen[c.gaussian] = 1;
  }
  scene->complete_surfels.clear();
  for (const SynthObject& object : scene->objects) {
    std::vector<uint32_t> members(object.num_gaussians);
    for (size_t k = 0; k < members.size(); ++k) {
      members[k] = static_cast<uint32_t>(object.first_gaussian + k);
    }
    scene->complete_surfels.push_back(scene->cloud.Subset(members));
  }
  std::vector<uint32_t> keep;
  for (uint32_t g = 0; g < seen.size(); ++g) {
    if (seen[g]) keep.push_back(g);
  }
  std::vector<uint16_t> ids;
  ids.reserve(keep.size());
  for (uint32_t g : keep) ids.push_back(scene->instance_ids[g]);
  // New ranges: count kept members of each object's old range.
  for (SynthObject& object : scene->objects) {
    size_t first = 0, count = 0;
    for (size_t k = 0; k < keep.size(); ++k) {
      if (keep[k] < object.first_gaussian) {
        first = k + 1;
      } else if (keep[k] < object.first_gaussian + object.num_gaussians) {
        ++count;
      }
    }
    object.first_gaussian = first;
    object.num_gaussians = count;
  }
  scene->cloud = scene->cloud.Subset(keep);
  scene->instance_ids = std::move(ids);
  return absl::OkStatus();
}

}  // namespace instascene
