// services/generation/completion_eval.h: completed objects scored against the ground truth of a
// synthetic scene (ALGORITHM.md section 8; docs/EVALUATION.md "Completion"), always for three
// versions of each object:
//   raw crop   - the observed surfels as they are (geometry: their centres; volume: the voxels
//                they occupy, a shell);
//   closed crop - the raw crop meshed exactly like the completed object (object_mesh.h), no prior:
//                what mere closing buys;
//   completed  - the output of the completion stage.
// Metrics: Chamfer distance (SyncDreamer convention, divided by the ground-truth bounding-box
// diagonal), F1 at tau = 1 %, 2 % and 5 % of that diagonal, volume IoU on a 64^3 grid, PSNR /
// SSIM at the known and the unknown ring views (against the object's complete ground-truth
// surfels, white background; the closed crop adds no splats, so its images are the raw crop's),
// hidden-surface recall (share of the ground-truth surface no real view sees that lies within
// tau = 2 % of the result), and free-space violations (completed surfels in space a real view saw
// empty: the rays from a camera through the surfel's one-pixel footprint all reach more than 1 % of
// the diagonal beyond it before the first ground-truth surface, and no ground-truth surface lies
// within that distance of the surfel). Thread-safe.
#pragma once

#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "absl/status/statusor.h"

namespace instascene::generation {

struct CompletionEvalOptions {
  std::vector<double> tau_fractions = {0.01, 0.02, 0.05};  // of the GT bounding-box diagonal
  double hidden_tau_fraction = 0.02;
  int samples = 20000;  // surface samples per mesh
  int volume_resolution = 64;
  uint64_t seed = 1;
  int num_threads = 0;
};

struct VersionScores {
  double chamfer = 0;      // / GT diagonal
  std::vector<double> f1;  // per tau
  double volume_iou = 0;
  double hidden_recall = 0;
  double psnr_known = 0, psnr_unknown = 0, ssim_known = 0, ssim_unknown = 0;
  int free_space_violations = 0;  // completed surfels only (0 for the crops)
};

struct ObjectCompletionEval {
  std::string directory;  // the object's output folder
  uint32_t id = 0;        // instance id
  int gt_id = 0;          // matched ground-truth object (0 = none)
  std::string gt_name, shape;
  bool abstained = false;
  double completed_share = 0;
  double hidden_share = 0;  // share of the GT surface no real view sees
  int known_views = 0, unknown_views = 0;
  VersionScores raw, closed, completed;
};

// `objects_dir` holds one folder per object (as the complete stage writes: manifest.json,
// object.ply, mesh.ply). The scene must be synthetic (gt/objects.json with meshes, and
// gt/complete/<id>.ply for the appearance metrics: scenes written with `synth --unseen drop`).
absl::StatusOr<std::vector<ObjectCompletionEval>> EvaluateCompletion(
    const std::string& scene_dir, const std::string& objects_dir,
    const CompletionEvalOptions& options);

nlohmann::json CompletionEvalJson(const std::vector<ObjectCompletionEval>& objects,
                                  const CompletionEvalOptions& options);

}  // namespace instascene::generation
