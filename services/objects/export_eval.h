// services/objects/export_eval.h: exported objects against a synthetic scene's ground truth, in
// metres: each exported object is matched to the ground-truth object with the smallest Chamfer
// distance, then (1) its bounding-box extents are compared with the ground-truth mesh's extents
// measured in the *exported* object frame (the same axes), and (2) its mesh, placed in the scene
// by `world_from_object`, is compared with the ground-truth mesh (Chamfer, surface samples), which
// checks the pose and the metric scale together.
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>
#include <nlohmann/json.hpp>

#include "absl/status/statusor.h"

namespace instascene::objects {

struct ExportObjectEval {
  uint32_t id = 0;     // exported object
  uint32_t gt_id = 0;  // matched ground-truth object
  std::string gt_name;
  Eigen::Vector3d extent = Eigen::Vector3d::Zero();     // exported, metres
  Eigen::Vector3d gt_extent = Eigen::Vector3d::Zero();  // ground truth in the exported frame
  double extent_error = 0;  // largest relative error over the three axes
  double chamfer = 0;       // metres, placed mesh vs ground-truth mesh
};

// `scene_dir` must hold ground truth (gt/objects.json with meshes) and meters_per_unit.
absl::StatusOr<std::vector<ExportObjectEval>> EvaluateExport(const std::string& scene_dir,
                                                             const std::string& export_dir);
nlohmann::json ExportEvalJson(const std::vector<ExportObjectEval>& evals);

}  // namespace instascene::objects
