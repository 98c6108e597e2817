// common/scene/transforms_json.cc: the transforms.json importer (instant-ngp / nerfstudio),
// declared in importers.h.
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <optional>

#include <nlohmann/json.hpp>

#include "absl/strings/str_cat.h"
#include "common/core/file_io.h"
#include "common/core/status.h"
#include "common/geometry/rigid.h"
#include "common/scene/importers.h"

namespace instascene {
using nlohmann::json;

namespace {

// A per-frame value, else the top-level one (nerfstudio allows both); false when neither is a
// number.
bool FrameNumber(const json& root, const json& frame, const char* key, double* value) {
  const json* src = frame.contains(key) ? &frame[key] : root.contains(key) ? &root[key] : nullptr;
  if (src == nullptr || !src->is_number()) return false;
  *value = src->get<double>();
  return true;
}

// The frame's pinhole intrinsics (fl_x or camera_angle_x; fl_y, cx, cy default from them); a
// non-zero distortion coefficient is refused unless the images are known to be undistorted.
absl::Status FrameIntrinsics(const json& root, const json& frame, const ImportOptions& options,
                             PinholeCamera* camera) {
  auto number = [&](const char* key, double* value) {
    return FrameNumber(root, frame, key, value);
  };
  double w = 0, h = 0, fl_x = 0, angle = 0;
  if (!number("w", &w) || !number("h", &h))
    return absl::InvalidArgumentError("missing image size \"w\"/\"h\"");
  if (!number("fl_x", &fl_x)) {
    if (!number("camera_angle_x", &angle))
      return absl::InvalidArgumentError("missing \"fl_x\" or \"camera_angle_x\"");
    fl_x = 0.5 * w / std::tan(0.5 * angle);
  }
  camera->width = static_cast<int>(std::lround(w));
  camera->height = static_cast<int>(std::lround(h));
  camera->fx = fl_x;
  if (!number("fl_y", &camera->fy)) camera->fy = fl_x;
  if (!number("cx", &camera->cx)) camera->cx = 0.5 * w;
  if (!number("cy", &camera->cy)) camera->cy = 0.5 * h;
  for (const char* key : {"k1", "k2", "k3", "k4", "p1", "p2"}) {
    double k = 0;
    if (number(key, &k) && k != 0.0 && !options.assume_undistorted) {
      return absl::InvalidArgumentError(
          absl::StrCat("lens distortion ", key, " = ", k,
                       " is not supported; undistort the images, or pass "
                       "--assume-undistorted if they already are"));
    }
  }
  return absl::OkStatus();
}

// camera_from_world from the frame's OpenGL-convention transform_matrix.
absl::StatusOr<Rigid3d> FrameCameraFromWorld(const json& frame) {
  if (!frame.contains("transform_matrix") || !frame["transform_matrix"].is_array() ||
      frame["transform_matrix"].size() < 3) {
    return absl::InvalidArgumentError("missing 4x4 \"transform_matrix\"");
  }
  Eigen::Matrix<double, 3, 4> gl_world_from_camera;
  try {
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 4; ++c)
        gl_world_from_camera(r, c) = frame["transform_matrix"][r].at(c).get<double>();
    }
  } catch (const json::exception& e) {
    return absl::InvalidArgumentError(absl::StrCat("bad \"transform_matrix\": ", e.what()));
  }
  // OpenGL camera axes (x right, y up, z backward) -> OpenCV (x right, y down, z forward).
  gl_world_from_camera.col(1) *= -1.0;
  gl_world_from_camera.col(2) *= -1.0;
  ASSIGN_OR_RETURN(const Rigid3d world_from_camera, RigidFromMatrix(gl_world_from_camera));
  return world_from_camera.Inverse();
}

// One frame as a view; nullopt when its image file is missing (NeRF synthetic omits extensions:
// .png, .jpg, .jpeg are tried).
absl::StatusOr<std::optional<SceneView>> ImportFrame(const json& root, const json& frame,
                                                     const std::filesystem::path& base,
                                                     const ImportOptions& options) {
  namespace fs = std::filesystem;
  if (!frame.is_object() || !frame.contains("file_path") || !frame["file_path"].is_string()) {
    return absl::InvalidArgumentError("missing \"file_path\"");
  }
  std::string file = frame["file_path"].get<std::string>();
  if (!fs::exists(base / file)) {
    for (const char* ext : {".png", ".jpg", ".jpeg"}) {
      if (fs::exists(base / (file + ext))) {
        file += ext;
        break;
      }
    }
  }
  SceneView view;
  RETURN_IF_ERROR(FrameIntrinsics(root, frame, options, &view.camera));
  if (!fs::exists(base / file)) return std::nullopt;
  ASSIGN_OR_RETURN(view.camera.camera_from_world, FrameCameraFromWorld(frame));
  view.name = fs::path(file).stem().string();
  view.image = file;
  RETURN_IF_ERROR(view.camera.Validate());
  return view;
}

}  // namespace

absl::StatusOr<ImportedCameras> ImportTransformsJson(const std::string& path,
                                                     const ImportOptions& options) {
  ASSIGN_OR_RETURN(std::string text, ReadFileBounded(path, size_t{256} << 20));
  json root = json::parse(text, nullptr, false);
  if (root.is_discarded() || !root.is_object())
    return absl::InvalidArgumentError(absl::StrCat(path, ": not a JSON object"));
  if (!root.contains("frames") || !root["frames"].is_array()) {
    return absl::InvalidArgumentError(absl::StrCat(path, ": no \"frames\" array"));
  }
  const std::filesystem::path base = std::filesystem::path(path).parent_path();
  ImportedCameras out;
  int skipped = 0;
  for (size_t i = 0; i < root["frames"].size(); ++i) {
    absl::StatusOr<std::optional<SceneView>> view =
        ImportFrame(root, root["frames"][i], base, options);
    if (!view.ok()) {
      return absl::InvalidArgumentError(
          absl::StrCat(path, ": frames[", i, "]: ", view.status().message()));
    }
    if (!view->has_value()) {
      ++skipped;
      continue;
    }
    out.views.push_back(std::move(**view));
  }
  if (skipped > 0) {
    out.warnings.push_back(absl::StrCat(skipped, " of ", root["frames"].size(),
                                        " frames skipped: image file missing"));
  }
  if (out.views.empty())
    return absl::InvalidArgumentError(absl::StrCat(path, ": no frame has an existing image"));
  std::sort(out.views.begin(), out.views.end(),
            [](const SceneView& a, const SceneView& b) { return a.name < b.name; });
  return out;
}

}  // namespace instascene
