// services/generation/completion_truth.h: a synthetic scene's ground truth as the completion
// evaluation (completion_eval.h) scores against it: each object's mesh, surface samples and which
// of them some real view sees; and the scores of one version of an object against it (geometry,
// volume, free space, appearance at the ring views). Thread-safe.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "absl/status/statusor.h"
#include "common/geometry/camera.h"
#include "common/geometry/triangle_mesh.h"
#include "common/mesh/ray_caster.h"
#include "common/scene/scene.h"
#include "common/splat/gaussian_cloud.h"
#include "services/generation/completion_eval.h"
#include "services/generation/object_frame.h"

namespace instascene::generation {

// One ground-truth object of a synthetic scene.
struct GroundTruthObject {
  int id = 0;
  std::string name, shape;
  TriangleMesh mesh;
  std::vector<Eigen::Vector3f> samples;
  std::vector<uint8_t> seen;  // per sample: some real view sees it
  double diagonal = 0;
  std::string complete_surfels;  // relative path, or empty
};

// The GT objects (each mesh sampled with `o.samples` points), and every GT surface (stuff and
// objects) as one mesh in `everything` with its caster. FailedPrecondition for a scene that is
// not synthetic.
absl::StatusOr<std::vector<GroundTruthObject>> ReadGroundTruth(const Scene& scene,
                                                               const CompletionEvalOptions& o,
                                                               TriangleMesh* everything,
                                                               std::unique_ptr<RayCaster>* caster);

// Chamfer (over the GT diagonal), F1 per tau and hidden-surface recall of `points` against `gt`.
VersionScores ScoreGeometry(const std::vector<Eigen::Vector3f>& points, const GroundTruthObject& gt,
                            const CompletionEvalOptions& o);

// Some real view saw through p: p is in its image and every ray from the camera through p's
// one-pixel footprint (p and p moved by half a pixel left, right, up, down at its depth) reaches
// more than `tolerance` beyond p before the first GT surface. A view observes free space at its
// pixel resolution; an exact ray alone would call points within a pixel of a silhouette seen.
bool InObservedFreeSpace(const Eigen::Vector3f& p, const std::vector<PinholeCamera>& cameras,
                         const RayCaster& scene, float tolerance);

// The voxels of a `r`^3 grid over `box` that hold a point (a raw crop's volume: a shell).
std::vector<uint8_t> ShellVoxels(const std::vector<Eigen::Vector3f>& points,
                                 const Eigen::AlignedBox3f& box, int r);

double Iou(const std::vector<uint8_t>& a, const std::vector<uint8_t>& b);

struct ViewScores {
  double psnr_known = 0, psnr_unknown = 0, ssim_known = 0, ssim_unknown = 0;
};

// Mean PSNR / SSIM of `prediction` against `truth` rendered alone at each ring camera, over the
// known and the unknown views apart.
absl::StatusOr<ViewScores> ScoreViews(const GaussianCloud& prediction, const GaussianCloud& truth,
                                      const std::vector<PinholeCamera>& ring,
                                      const std::vector<bool>& known, const ObjectFrame& frame,
                                      int threads);

}  // namespace instascene::generation
