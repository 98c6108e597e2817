#include "services/generation/completion_eval.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <functional>
#include <limits>
#include <optional>

#include "absl/strings/str_cat.h"
#include "common/core/json_file.h"
#include "common/core/status.h"
#include "common/eval/geometry_metrics.h"
#include "common/geometry/point_index.h"
#include "common/mesh/mesh_ply.h"
#include "common/mesh/mesh_volume.h"
#include "common/mesh/ray_caster.h"
#include "common/mesh/surface_distance.h"
#include "common/mesh/surfel_mesh.h"
#include "common/scene/scene.h"
#include "common/splat/gaussian_ply.h"
#include "services/generation/completion.h"
#include "services/generation/completion_truth.h"
#include "services/generation/free_space.h"
#include "services/generation/manifest_options.h"
#include "services/generation/object_mesh.h"
#include "services/generation/viewpoints.h"

namespace instascene::generation {
namespace {

namespace fs = std::filesystem;

std::vector<Eigen::Vector3f> Centres(const GaussianCloud& cloud) {
  std::vector<Eigen::Vector3f> out(cloud.size());
  for (size_t g = 0; g < cloud.size(); ++g) out[g] = Eigen::Vector3f(&cloud.positions[3 * g]);
  return out;
}

// The object folders under `objects_dir` (those with a manifest), in id order.
absl::StatusOr<std::vector<std::string>> ObjectDirectories(const std::string& objects_dir) {
  std::vector<std::string> dirs;
  std::error_code ec;
  for (const auto& entry : fs::directory_iterator(objects_dir, ec)) {
    if (entry.is_directory() && fs::exists(entry.path() / "manifest.json")) {
      dirs.push_back(entry.path().string());
    }
  }
  if (ec) return absl::NotFoundError(absl::StrCat(objects_dir, ": ", ec.message()));
  std::sort(dirs.begin(), dirs.end(), [](const std::string& a, const std::string& b) {
    const std::string na = fs::path(a).filename().string(), nb = fs::path(b).filename().string();
    return na.size() != nb.size() ? na.size() < nb.size() : na < nb;
  });
  return dirs;
}

// The ground-truth object most of the raw crop lies on (within 2 % of its diagonal); truth.size()
// when none holds any of it.
size_t MatchGroundTruth(const std::vector<Eigen::Vector3f>& raw_points,
                        const std::vector<GroundTruthObject>& truth,
                        const std::vector<std::unique_ptr<PointIndex3>>& truth_index) {
  size_t best = truth.size(), best_count = 0;
  for (size_t t = 0; t < truth.size(); ++t) {
    const float tau = static_cast<float>(0.02 * truth[t].diagonal);
    size_t count = 0;
    for (const Eigen::Vector3f& p : raw_points) {
      count += truth_index[t]->Nearest(p).second <= tau * tau;
    }
    if (count > best_count) {
      best = t;
      best_count = count;
    }
  }
  return best;
}

// What one evaluation shares across its objects.
struct EvalContext {
  const Scene& scene;
  const std::vector<PinholeCamera>& cameras;
  const RayCaster& truth_caster;                      // every GT surface
  const SurfaceDistance& truth_surfaces;              // likewise, exact distances
  std::unique_ptr<RayCaster> scene_caster = nullptr;  // the scene's splats, read when first needed
};

// The raw crop meshed as the completion meshes (its manifest's options), without a prior and so
// without an axis: its closing keeps the renders' visual hull inside wherever the completion's
// would (completion.cc), against the same free space of the capture (the scene's splats carved by
// the real views, as the completion carved it).
absl::StatusOr<TriangleMesh> ClosedCrop(const GaussianCloud& raw, const ObjectFrame& frame,
                                        const nlohmann::json& m, const CompletionEvalOptions& o,
                                        EvalContext* context) {
  const MeshingOptions meshing = MeshingFromManifest(m);
  if (!meshing.closed || !meshing.enclose_hull) {
    return MeshObject(raw, frame, meshing, o.num_threads);
  }
  if (context->scene_caster == nullptr) {
    ASSIGN_OR_RETURN(GaussianCloud cloud, ReadSceneGaussians(context->scene));
    cloud = ToSurfels(cloud);
    std::vector<uint32_t> everything(cloud.size());
    for (uint32_t g = 0; g < everything.size(); ++g) everything[g] = g;
    ASSIGN_OR_RETURN(context->scene_caster,
                     RayCaster::Create(SurfelDiscs(cloud, everything, SurfelDiscOptions{})));
  }
  ASSIGN_OR_RETURN(const FreeSpaceGrid free_space,
                   FreeSpaceGrid::Carve(context->cameras, *context->scene_caster, frame,
                                        FreeSpaceFromManifest(m)));
  return MeshObject(raw, frame, meshing, o.num_threads,
                    [&](const Eigen::Vector3f& p) { return free_space.IsFree(p); });
}

// Volume IoU of the three versions, on one grid per object spanning the truth and all of them.
absl::Status ScoreVolumes(const GroundTruthObject& gt, const std::vector<Eigen::Vector3f>& raw,
                          const TriangleMesh& closed, const TriangleMesh& completed,
                          const CompletionEvalOptions& o, ObjectCompletionEval* e) {
  Eigen::AlignedBox3f box = gt.mesh.Bounds();
  for (const Eigen::Vector3f& p : raw) box.extend(p);
  box.extend(closed.Bounds());
  box.extend(completed.Bounds());
  box.extend(box.min() - 0.01f * box.sizes());
  box.extend(box.max() + 0.01f * box.sizes());
  const int r = o.volume_resolution;
  ASSIGN_OR_RETURN(const std::vector<uint8_t> truth_voxels, VoxelizeByRayParity(gt.mesh, box, r));
  ASSIGN_OR_RETURN(const std::vector<uint8_t> closed_voxels, VoxelizeByRayParity(closed, box, r));
  ASSIGN_OR_RETURN(const std::vector<uint8_t> completed_voxels,
                   VoxelizeByRayParity(completed, box, r));
  e->raw.volume_iou = Iou(ShellVoxels(raw, box, r), truth_voxels);
  e->closed.volume_iou = Iou(closed_voxels, truth_voxels);
  e->completed.volume_iou = Iou(completed_voxels, truth_voxels);
  return absl::OkStatus();
}

// Completed surfels a real view saw through, away from every GT surface (a surfel on a surface is
// no violation, whatever the pixel quantisation of the views).
int FreeSpaceViolations(const GaussianCloud& object, const std::vector<uint32_t>& added,
                        const GroundTruthObject& gt, const EvalContext& context) {
  const float tolerance = static_cast<float>(0.01 * gt.diagonal);
  std::vector<Eigen::Vector3f> seen_through;
  for (uint32_t g : added) {
    const Eigen::Vector3f p(&object.positions[3 * g]);
    if (InObservedFreeSpace(p, context.cameras, context.truth_caster, tolerance)) {
      seen_through.push_back(p);
    }
  }
  int violations = 0;
  for (float d : context.truth_surfaces.Distances(seen_through)) violations += d > tolerance;
  return violations;
}

// Appearance at the ring views, against the object's complete GT surfels (when the scene has them).
absl::Status ScoreAppearance(const GaussianCloud& raw, const GaussianCloud& object,
                             const GroundTruthObject& gt, const ObjectFrame& frame,
                             const nlohmann::json& m, const CompletionEvalOptions& o,
                             const EvalContext& context, ObjectCompletionEval* e) {
  std::vector<bool> known;
  const RingOptions ring = RingFromManifest(m, &known);
  for (bool k : known) (k ? e->known_views : e->unknown_views)++;
  if (gt.complete_surfels.empty()) return absl::OkStatus();
  ASSIGN_OR_RETURN(GaussianCloud complete,
                   ReadGaussianPly(context.scene.Path(gt.complete_surfels)));
  const std::vector<PinholeCamera> cameras_ring = RingCameras(frame, ring);
  ASSIGN_OR_RETURN(ViewScores raw_views,
                   ScoreViews(raw, complete, cameras_ring, known, frame, o.num_threads));
  ASSIGN_OR_RETURN(ViewScores done_views,
                   ScoreViews(object, complete, cameras_ring, known, frame, o.num_threads));
  auto assign = [](const ViewScores& from, VersionScores* to) {
    to->psnr_known = from.psnr_known;
    to->psnr_unknown = from.psnr_unknown;
    to->ssim_known = from.ssim_known;
    to->ssim_unknown = from.ssim_unknown;
  };
  assign(raw_views, &e->raw);  // the closed crop adds no splats: its images are the raw crop's
  assign(raw_views, &e->closed);
  assign(done_views, &e->completed);
  return absl::OkStatus();
}

// One object folder scored against the ground truth.
absl::StatusOr<ObjectCompletionEval> EvaluateObject(
    const std::string& dir, const std::vector<GroundTruthObject>& truth,
    const std::vector<std::unique_ptr<PointIndex3>>& truth_index, const CompletionEvalOptions& o,
    EvalContext* context) {
  ObjectCompletionEval e;
  e.directory = dir;
  ASSIGN_OR_RETURN(nlohmann::json m,
                   ReadJsonFile((fs::path(dir) / "manifest.json").string(), 256 << 20));
  ASSIGN_OR_RETURN(GaussianCloud object, ReadGaussianPly((fs::path(dir) / "object.ply").string()));
  ASSIGN_OR_RETURN(TriangleMesh completed_mesh, ReadMeshPly((fs::path(dir) / "mesh.ply").string()));
  const ExtraChannel* provenance = object.FindExtra(kProvenanceChannel);
  if (provenance == nullptr) {
    return absl::DataLossError(absl::StrCat(dir, "/object.ply has no provenance property"));
  }
  std::vector<uint32_t> observed, added;
  for (uint32_t g = 0; g < object.size(); ++g) {
    (provenance->values[g] == 0 ? observed : added).push_back(g);
  }
  const GaussianCloud raw = object.Subset(observed);
  const std::vector<Eigen::Vector3f> raw_points = Centres(raw);
  e.id = m.at("id").get<uint32_t>();
  e.abstained = m.value("abstained", false);
  e.completed_share = object.size() ? static_cast<double>(added.size()) / object.size() : 0;
  ObjectFrame frame = FrameFromManifest(m);
  if (!m["frame"].contains("bottom")) {  // manifests before 2026-12-05: the raw crop's lowest
    frame.bottom_height = std::numeric_limits<float>::infinity();
    for (const Eigen::Vector3f& p : raw_points) {
      frame.bottom_height = std::min(frame.bottom_height, frame.up.dot(p));
    }
  }
  const size_t best = MatchGroundTruth(raw_points, truth, truth_index);
  if (best == truth.size()) return e;  // nothing matched: reported with gt_id 0
  const GroundTruthObject& gt = truth[best];
  e.gt_id = gt.id;
  e.gt_name = gt.name;
  e.shape = gt.shape;
  size_t hidden = 0;
  for (uint8_t s : gt.seen) hidden += !s;
  e.hidden_share = static_cast<double>(hidden) / std::max<size_t>(1, gt.seen.size());
  ASSIGN_OR_RETURN(const TriangleMesh closed_mesh, ClosedCrop(raw, frame, m, o, context));
  e.raw = ScoreGeometry(raw_points, gt, o);
  e.closed = ScoreGeometry(SampleSurface(closed_mesh, o.samples, o.seed + 1), gt, o);
  e.completed = ScoreGeometry(SampleSurface(completed_mesh, o.samples, o.seed + 2), gt, o);
  RETURN_IF_ERROR(ScoreVolumes(gt, raw_points, closed_mesh, completed_mesh, o, &e));
  e.completed.free_space_violations = FreeSpaceViolations(object, added, gt, *context);
  RETURN_IF_ERROR(ScoreAppearance(raw, object, gt, frame, m, o, *context, &e));
  return e;
}

absl::StatusOr<std::vector<ObjectCompletionEval>> Evaluate(const std::string& scene_dir,
                                                           const std::string& objects_dir,
                                                           const CompletionEvalOptions& o) {
  ASSIGN_OR_RETURN(Scene scene, ReadScene(scene_dir));
  std::vector<PinholeCamera> cameras;
  for (const SceneView& v : scene.views) cameras.push_back(v.camera);
  std::unique_ptr<RayCaster> caster;
  TriangleMesh all_meshes;
  ASSIGN_OR_RETURN(std::vector<GroundTruthObject> truth,
                   ReadGroundTruth(scene, o, &all_meshes, &caster));
  // Every GT surface (objects and stuff), for "is p on some surface": the exact distance (400k
  // samples of the scene stood up to two of an object's surfel spacings off its surface, and
  // counted surfels on it as violations).
  ASSIGN_OR_RETURN(const std::unique_ptr<SurfaceDistance> surfaces,
                   SurfaceDistance::Create(all_meshes));
  std::vector<std::unique_ptr<PointIndex3>> truth_index;
  for (const GroundTruthObject& gt : truth) {
    truth_index.push_back(std::make_unique<PointIndex3>(gt.samples));
  }
  ASSIGN_OR_RETURN(const std::vector<std::string> dirs, ObjectDirectories(objects_dir));
  EvalContext context{scene, cameras, *caster, *surfaces};
  std::vector<ObjectCompletionEval> results;
  for (const std::string& dir : dirs) {
    ASSIGN_OR_RETURN(ObjectCompletionEval e, EvaluateObject(dir, truth, truth_index, o, &context));
    results.push_back(std::move(e));
  }
  return results;
}

}  // namespace

absl::StatusOr<std::vector<ObjectCompletionEval>> EvaluateCompletion(
    const std::string& scene_dir, const std::string& objects_dir, const CompletionEvalOptions& o) {
  // Manifests and ground-truth files are user input: a missing or mistyped key is an error
  // naming the folders, never an exception out of the command.
  try {
    return Evaluate(scene_dir, objects_dir, o);
  } catch (const nlohmann::json::exception& e) {
    return absl::DataLossError(
        absl::StrCat(objects_dir, " or ", scene_dir, ": malformed JSON field: ", e.what()));
  }
}

namespace {

nlohmann::json VersionJson(const VersionScores& v, const CompletionEvalOptions& o) {
  nlohmann::json f1 = nlohmann::json::object();
  for (size_t t = 0; t < v.f1.size(); ++t) f1[absl::StrCat(o.tau_fractions[t])] = v.f1[t];
  return nlohmann::json{{"chamfer", v.chamfer},
                        {"f1", f1},
                        {"volume_iou", v.volume_iou},
                        {"hidden_recall", v.hidden_recall},
                        {"psnr_known", v.psnr_known},
                        {"psnr_unknown", v.psnr_unknown},
                        {"ssim_known", v.ssim_known},
                        {"ssim_unknown", v.ssim_unknown},
                        {"free_space_violations", v.free_space_violations}};
}

nlohmann::json ObjectJson(const ObjectCompletionEval& e, const CompletionEvalOptions& o) {
  return {{"id", e.id},
          {"gt_id", e.gt_id},
          {"gt_name", e.gt_name},
          {"shape", e.shape},
          {"abstained", e.abstained},
          {"completed_share", e.completed_share},
          {"hidden_share", e.hidden_share},
          {"known_views", e.known_views},
          {"unknown_views", e.unknown_views},
          {"raw", VersionJson(e.raw, o)},
          {"closed", VersionJson(e.closed, o)},
          {"completed", VersionJson(e.completed, o)}};
}

// Per version: the sums of its scores (chamfer, volume IoU, hidden recall, PSNR and SSIM known /
// unknown, violations, then F1 per tau) over the matched objects.
using VersionSums = std::map<std::string, std::vector<double>>;
void AddToSums(const ObjectCompletionEval& e, VersionSums* sums) {
  for (const auto& [name, v] :
       {std::pair{"raw", &e.raw}, {"closed", &e.closed}, {"completed", &e.completed}}) {
    auto& s = (*sums)[name];
    s.resize(8 + v->f1.size(), 0.0);
    s[0] += v->chamfer;
    s[1] += v->volume_iou;
    s[2] += v->hidden_recall;
    s[3] += v->psnr_known;
    s[4] += v->psnr_unknown;
    s[5] += v->ssim_known;
    s[6] += v->ssim_unknown;
    s[7] += v->free_space_violations;
    for (size_t t = 0; t < v->f1.size(); ++t) s[8 + t] += v->f1[t];
  }
}

// The means per version (violations summed).
nlohmann::json MeansJson(const VersionSums& sums, int matched, const CompletionEvalOptions& o) {
  nlohmann::json mean = nlohmann::json::object();
  for (const auto& [name, s] : sums) {
    nlohmann::json f1 = nlohmann::json::object();
    for (size_t t = 8; t < s.size(); ++t) f1[absl::StrCat(o.tau_fractions[t - 8])] = s[t] / matched;
    mean[name] = {{"chamfer", s[0] / matched},
                  {"volume_iou", s[1] / matched},
                  {"hidden_recall", s[2] / matched},
                  {"psnr_known", s[3] / matched},
                  {"psnr_unknown", s[4] / matched},
                  {"ssim_known", s[5] / matched},
                  {"ssim_unknown", s[6] / matched},
                  {"free_space_violations", s[7]},
                  {"f1", f1}};
  }
  return mean;
}

}  // namespace

nlohmann::json CompletionEvalJson(const std::vector<ObjectCompletionEval>& objects,
                                  const CompletionEvalOptions& o) {
  nlohmann::json list = nlohmann::json::array();
  VersionSums sums;
  int matched = 0;
  for (const ObjectCompletionEval& e : objects) {
    list.push_back(ObjectJson(e, o));
    if (e.gt_id == 0) continue;
    ++matched;
    AddToSums(e, &sums);
  }
  return {{"objects", list},
          {"matched", matched},
          {"mean", MeansJson(sums, matched, o)},
          {"tau_fractions", o.tau_fractions},
          {"hidden_tau_fraction", o.hidden_tau_fraction}};
}

}  // namespace instascene::generation
