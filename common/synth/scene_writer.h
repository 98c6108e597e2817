// common/synth/scene_writer.h: writes a generated ClutterScene as a scene directory.
//
// Layout (docs/SCENE_FORMAT.md): scene.json, gaussians.ply (no ground truth in it), images/*.png
// rendered with the project's rasterizer, and gt/ with the ground truth. Files are written
// atomically; progress goes to the optional callback. Not thread-safe per call target directory.
#pragma once

#include <functional>
#include <string>

#include "absl/status/status.h"
#include "common/synth/cluttered_scene.h"

namespace instascene {

struct SceneWriteOptions {
  int num_threads = 0;  // rasterizer threads (0 = all)
  std::function<void(int done, int total)> progress;  // called after each view
};

absl::Status WriteClutterScene(const ClutterScene& scene, const std::string& directory,
                               const SceneWriteOptions& options = {});

}  // namespace instascene
