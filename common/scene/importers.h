// common/scene/importers.h: camera importers into scene views (COLMAP models, transforms.json).
//
// Both return views sorted by image name (InstaScene's "adjacent views" are neighbours in name
// order, ALGORITHM.md 1) with image paths relative to the importer's image folder. Distorted camera
// models are rejected with a clear message unless `assume_undistorted` says the images were already
// undistorted (then the distortion terms are dropped). Stateless, thread-safe.
#pragma once

#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "common/scene/scene.h"

namespace instascene {

struct ImportOptions {
  bool assume_undistorted = false;  // accept distorted models, ignoring their distortion terms
};

struct ImportedCameras {
  std::vector<SceneView> views;       // image = file name relative to the image folder
  std::vector<std::string> warnings;  // e.g. frames skipped because their image is missing
};

// Reads <model_dir>/{cameras,images}.bin, or the .txt pair when the .bin files are absent.
absl::StatusOr<ImportedCameras> ImportColmapModel(const std::string& model_dir,
                                                  const ImportOptions& options = {});

// Reads an instant-ngp / nerfstudio transforms.json (OpenGL camera-to-world) into OpenCV
// camera_from_world. Frames whose image file does not exist are skipped with a warning; image
// paths are resolved relative to the JSON file's folder.
absl::StatusOr<ImportedCameras> ImportTransformsJson(const std::string& path,
                                                     const ImportOptions& options = {});

}  // namespace instascene
