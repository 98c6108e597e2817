// common/synth/scene_writer.h: writes a generated ClutterScene as a scene directory.
//
// Layout (docs/SYNTHETIC.md): scene.json, gaussians.ply (no ground truth in it), images/*.png
// rendered with the project's rasterizer, masks/*.png from the simulated segmenter, and gt/:
//   gt/masks/<view>.png     16-bit instance id per pixel: the instance with the largest total
//                           blending weight at the pixel; 0 = stuff/background or alpha < 0.5
//   gt/instances.ply        one `instance_id` (ushort) per Gaussian, in gaussians.ply order
//   gt/objects.json         id, name, shape, size, pose, duplicate group, Gaussian range, colour
//   gt/meshes/<id>.ply      the complete object surface (triangle mesh, world frame)
// Files are written atomically; progress goes to the optional callback.
#pragma once

#include <functional>
#include <string>

#include "absl/status/status.h"
#include "common/raster/render_types.h"
#include "common/scene/image_io.h"
#include "common/splat/gaussian_cloud.h"
#include "common/synth/cluttered_scene.h"
#include "common/synth/mask_noise.h"

namespace instascene {

struct SceneWriteOptions {
  std::string mask_noise = "medium";  // none, low, medium, high (MaskNoiseOptions::Level)
  uint64_t seed = 1;                  // noise seed (view v uses seed * 1000003 + v)
  int num_threads = 0;                // rasterizer threads (0 = all)
  std::function<void(int done, int total)> progress;  // called after each view
};

// Ground-truth instance map of one view: per pixel, the instance id with the largest summed
// blending weight (0 when that is stuff, or alpha < 0.5).
LabelMap GroundTruthInstanceMap(const RenderResult& traced,
                                const std::vector<uint32_t>& instance_ids);

absl::Status WriteClutterScene(const ClutterScene& scene, const std::string& directory,
                               const SceneWriteOptions& options = {});

}  // namespace instascene
