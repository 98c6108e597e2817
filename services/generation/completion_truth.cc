#include "services/generation/completion_truth.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <filesystem>

#include "absl/strings/str_cat.h"
#include "common/core/json_file.h"
#include "common/core/status.h"
#include "common/eval/geometry_metrics.h"
#include "common/eval/metrics.h"
#include "common/geometry/point_index.h"
#include "common/mesh/mesh_checks.h"
#include "common/mesh/mesh_ply.h"
#include "services/generation/object_mesh.h"
#include "services/generation/seen_through.h"

namespace instascene::generation {
namespace {

// A real view sees p when p is in its image and nothing of the GT scene lies in front of it.
bool SeenBySomeView(const Eigen::Vector3f& p, const std::vector<PinholeCamera>& cameras,
                    const RayCaster& scene, float tolerance) {
  for (const PinholeCamera& c : cameras) {
    if (!c.SeesPoint(p.cast<double>())) continue;
    const Eigen::Vector3f o = c.CenterInWorld().cast<float>();
    const float line = (p - o).norm();
    if (!scene.Cast(o, (p - o) / line, 0.0f, line - tolerance).hit) return true;
  }
  return false;
}

Image ToImage(const ViewImages& v) { return Image{v.camera.width, v.camera.height, 3, v.rgb}; }

}  // namespace

// Some real view saw through p: p is in its image and every ray from the camera through p's
// one-pixel footprint (p and p moved by half a pixel left, right, up, down at its depth) reaches
// more than `tolerance` beyond p before the first GT surface. A view observes free space at its
// pixel resolution; an exact ray alone would call points within a pixel of a silhouette seen.
bool InObservedFreeSpace(const Eigen::Vector3f& p, const std::vector<PinholeCamera>& cameras,
                         const RayCaster& scene, float tolerance) {
  for (const PinholeCamera& c : cameras) {
    std::array<Eigen::Vector3f, 5> footprint;
    if (!PixelFootprint(c, p, &footprint)) continue;
    const Eigen::Vector3f o = c.CenterInWorld().cast<float>();
    bool all_clear = true;
    for (const Eigen::Vector3f& q : footprint) {
      const float line = (q - o).norm();
      if (scene.Cast(o, (q - o) / line, 0.0f, line + tolerance).hit) {
        all_clear = false;
        break;
      }
    }
    if (all_clear) return true;
  }
  return false;
}

std::vector<uint8_t> ShellVoxels(const std::vector<Eigen::Vector3f>& points,
                                 const Eigen::AlignedBox3f& box, int r) {
  std::vector<uint8_t> voxels(static_cast<size_t>(r) * r * r, 0);
  const Eigen::Vector3f cell = box.sizes() / static_cast<float>(r);
  for (const Eigen::Vector3f& p : points) {
    const Eigen::Vector3i c = ((p - box.min()).array() / cell.array()).floor().cast<int>();
    if ((c.array() < 0).any() || (c.array() >= r).any()) continue;
    voxels[(static_cast<size_t>(c.z()) * r + c.y()) * r + c.x()] = 1;
  }
  return voxels;
}

double Iou(const std::vector<uint8_t>& a, const std::vector<uint8_t>& b) {
  size_t inter = 0, uni = 0;
  for (size_t i = 0; i < a.size(); ++i) {
    inter += a[i] && b[i];
    uni += a[i] || b[i];
  }
  return uni ? static_cast<double>(inter) / uni : 0.0;
}

absl::StatusOr<ViewScores> ScoreViews(const GaussianCloud& prediction, const GaussianCloud& truth,
                                      const std::vector<PinholeCamera>& ring,
                                      const std::vector<bool>& known, const ObjectFrame& frame,
                                      int threads) {
  ViewScores s;
  int nk = 0, nu = 0;
  for (size_t k = 0; k < ring.size(); ++k) {
    ASSIGN_OR_RETURN(ViewImages a, RenderObjectView(prediction, ring[k], frame, threads));
    ASSIGN_OR_RETURN(ViewImages b, RenderObjectView(truth, ring[k], frame, threads));
    ASSIGN_OR_RETURN(double psnr, Psnr(ToImage(a), ToImage(b)));
    ASSIGN_OR_RETURN(double ssim, Ssim(ToImage(a), ToImage(b)));
    psnr = std::min(psnr, 100.0);
    if (known[k]) {
      s.psnr_known += psnr;
      s.ssim_known += ssim;
      ++nk;
    } else {
      s.psnr_unknown += psnr;
      s.ssim_unknown += ssim;
      ++nu;
    }
  }
  if (nk) s.psnr_known /= nk, s.ssim_known /= nk;
  if (nu) s.psnr_unknown /= nu, s.ssim_unknown /= nu;
  return s;
}

VersionScores ScoreGeometry(const std::vector<Eigen::Vector3f>& points, const GroundTruthObject& gt,
                            const CompletionEvalOptions& o) {
  VersionScores v;
  for (double tau : o.tau_fractions) {
    const PointCloudComparison c = ComparePointClouds(points, gt.samples, tau * gt.diagonal);
    v.f1.push_back(c.f1);
    v.chamfer = c.chamfer / gt.diagonal;
  }
  if (!points.empty()) {
    const PointIndex3 index(points);
    const float tau = static_cast<float>(o.hidden_tau_fraction * gt.diagonal);
    size_t hidden = 0, covered = 0;
    for (size_t i = 0; i < gt.samples.size(); ++i) {
      if (gt.seen[i]) continue;
      ++hidden;
      covered += index.Nearest(gt.samples[i]).second <= tau * tau;
    }
    v.hidden_recall = hidden ? static_cast<double>(covered) / hidden : 1.0;
  }
  return v;
}

absl::StatusOr<std::vector<GroundTruthObject>> ReadGroundTruth(const Scene& scene,
                                                               const CompletionEvalOptions& o,
                                                               TriangleMesh* everything,
                                                               std::unique_ptr<RayCaster>* caster) {
  if (!std::filesystem::exists(scene.Path("gt/meshes/stuff.ply"))) {
    return absl::FailedPreconditionError(absl::StrCat(
        scene.directory, ": gt/meshes/stuff.ply missing (regenerate the scene with synth)"));
  }
  ASSIGN_OR_RETURN(nlohmann::json objects, ReadJsonFile(scene.Path("gt/objects.json"), 256 << 20));
  std::vector<GroundTruthObject> out;
  ASSIGN_OR_RETURN(*everything, ReadMeshPly(scene.Path("gt/meshes/stuff.ply")));
  for (const nlohmann::json& j : objects) {
    if (!j.contains("mesh") || j["mesh"].is_null()) {
      return absl::FailedPreconditionError(
          absl::StrCat(scene.directory, ": object ", j.value("name", "?"),
                       " has no ground-truth mesh (completion needs a synthetic scene)"));
    }
    GroundTruthObject gt;
    gt.id = j.at("id").get<int>();
    gt.name = j.value("name", "");
    gt.shape = j.value("shape", "");
    gt.complete_surfels = j.value("complete_surfels", "");
    ASSIGN_OR_RETURN(gt.mesh, ReadMeshPly(scene.Path(j.at("mesh").get<std::string>())));
    gt.diagonal = gt.mesh.Bounds().diagonal().norm();
    gt.samples = SampleSurface(gt.mesh, o.samples, o.seed * 7919 + gt.id);
    everything->Append(gt.mesh);
    out.push_back(std::move(gt));
  }
  everything->colors.clear();
  ASSIGN_OR_RETURN(*caster, RayCaster::Create(*everything));
  std::vector<PinholeCamera> cameras;
  for (const SceneView& v : scene.views) cameras.push_back(v.camera);
  for (GroundTruthObject& gt : out) {
    gt.seen.assign(gt.samples.size(), 0);
    const float tolerance = static_cast<float>(0.002 * gt.diagonal);
    tbb::parallel_for(size_t{0}, gt.samples.size(), [&](size_t i) {
      gt.seen[i] = SeenBySomeView(gt.samples[i], cameras, **caster, tolerance);
    });
  }
  return out;
}

}  // namespace instascene::generation
