// common/scene/scene.h: the scene directory, the on-disk and upload format (ARCHITECTURE.md 3).
//
//   <scene>/scene.json      {"format": "instascene.scene/1", "gaussians": "gaussians.ply",
//                            "views": [{name, image, mask, width, height, fx, fy, cx, cy,
//                                       camera_from_world: 3x4 rows}], ...}
//   <scene>/gaussians.ply   Inria/2DGS layout
//   <scene>/images/, masks/, optional gt/
// Paths inside scene.json are relative to the scene directory and may not leave it. Unknown
// top-level keys (e.g. "gt") are kept in `metadata` and written back. Value types; thread-safe.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"
#include "common/geometry/camera.h"
#include "common/splat/gaussian_cloud.h"

namespace instascene {

inline constexpr char kSceneFormat[] = "instascene.scene/1";

struct SceneView {
  std::string name;   // unique within the scene
  std::string image;  // relative path of the RGB image ("" = none)
  std::string mask;   // relative path of the 2D instance label map ("" = none)
  PinholeCamera camera;
};

struct Scene {
  std::string directory;                    // where scene.json lives
  std::string gaussians = "gaussians.ply";  // relative path of the splat model
  std::vector<SceneView> views;
  // Metric scale: metres per scene unit (scene.json `meters_per_unit`, optional; importers take
  // --meters-per-unit, synthetic scenes set it). Absent: sizes stay in scene units, never guessed.
  std::optional<double> meters_per_unit;
  nlohmann::json metadata = nlohmann::json::object();  // other top-level keys, kept verbatim

  std::string Path(const std::string& relative) const;  // directory / relative
  int FindView(absl::string_view name) const;           // index or -1
};

// Parses scene.json text; `source` names it in errors. Checks the format tag, unique view names,
// safe relative paths and valid cameras.
absl::StatusOr<Scene> ParseSceneJson(absl::string_view text, absl::string_view source);
std::string SceneToJson(const Scene& scene);

// Reads and validates <directory>/scene.json (no images or splats are loaded).
absl::StatusOr<Scene> ReadScene(const std::string& directory);
// Writes <scene.directory>/scene.json atomically, creating the directory.
absl::Status WriteScene(const Scene& scene);

// A view by name, or by decimal index when no view has that name.
absl::StatusOr<int> ResolveView(const Scene& scene, absl::string_view name_or_index);

absl::StatusOr<GaussianCloud> ReadSceneGaussians(const Scene& scene);
// A view's image and mask: ReadViewImage / ReadViewMask in common/scene/image_io.h (OpenImageIO
// stays out of this header, so the store and the scheduler can parse scenes without it).

}  // namespace instascene
