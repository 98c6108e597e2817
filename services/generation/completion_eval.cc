#include "services/generation/completion_eval.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <filesystem>
#include <functional>
#include <limits>
#include <map>
#include <optional>

#include "absl/strings/str_cat.h"
#include "common/core/file_io.h"
#include "common/core/status.h"
#include "common/eval/geometry_metrics.h"
#include "common/eval/metrics.h"
#include "common/geometry/point_index.h"
#include "common/mesh/mesh_checks.h"
#include "common/mesh/mesh_ply.h"
#include "common/mesh/mesh_volume.h"
#include "common/mesh/ray_caster.h"
#include "common/mesh/surface_distance.h"
#include "common/mesh/surfel_mesh.h"
#include "common/scene/image_io.h"
#include "common/scene/scene.h"
#include "common/splat/gaussian_ply.h"
#include "services/generation/completion.h"
#include "services/generation/free_space.h"
#include "services/generation/object_mesh.h"
#include "services/generation/seen_through.h"
#include "services/generation/viewpoints.h"

namespace instascene::generation {
namespace {

namespace fs = std::filesystem;

struct GroundTruthObject {
  int id = 0;
  std::string name, shape;
  TriangleMesh mesh;
  std::vector<Eigen::Vector3f> samples;
  std::vector<uint8_t> seen;  // per sample: some real view sees it
  double diagonal = 0;
  std::string complete_surfels;  // relative path, or empty
};

absl::StatusOr<nlohmann::json> ReadJson(const std::string& path) {
  ASSIGN_OR_RETURN(std::string text, ReadFileBounded(path, 256 << 20));
  nlohmann::json j = nlohmann::json::parse(text, nullptr, false);
  if (j.is_discarded()) return absl::DataLossError(absl::StrCat(path, ": not JSON"));
  return j;
}

Eigen::Vector3f Vec3(const nlohmann::json& j) {
  return {j.at(0).get<float>(), j.at(1).get<float>(), j.at(2).get<float>()};
}

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

Image ToImage(const ViewImages& v) { return Image{v.camera.width, v.camera.height, 3, v.rgb}; }

struct ViewScores {
  double psnr_known = 0, psnr_unknown = 0, ssim_known = 0, ssim_unknown = 0;
};

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

VersionScores Geometry(const std::vector<Eigen::Vector3f>& points, const GroundTruthObject& gt,
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

std::vector<Eigen::Vector3f> Centres(const GaussianCloud& cloud) {
  std::vector<Eigen::Vector3f> out(cloud.size());
  for (size_t g = 0; g < cloud.size(); ++g) out[g] = Eigen::Vector3f(&cloud.positions[3 * g]);
  return out;
}

ObjectFrame FrameFromManifest(const nlohmann::json& m) {
  ObjectFrame f;
  const nlohmann::json& j = m.at("frame");
  f.center = Vec3(j.at("center"));
  f.up = Vec3(j.at("up"));
  f.radius = j.at("radius").get<float>();
  f.spacing = j.at("spacing").get<float>();
  if (j.contains("bottom")) f.bottom_height = j["bottom"].get<float>();
  f.has_support = !j.at("support").is_null();
  if (f.has_support) f.support_height = j.at("support").get<float>();
  return f;
}

FreeSpaceOptions FreeSpaceFromManifest(const nlohmann::json& m) {
  FreeSpaceOptions f;
  if (!m.contains("free_space")) return f;  // manifests before 2026-12-05 ran the defaults
  const nlohmann::json& j = m["free_space"];
  f.resolution = j.value("resolution", f.resolution);
  f.extent_radii = j.value("extent_radii", f.extent_radii);
  f.min_views = j.value("min_views", f.min_views);
  f.margin_voxels = j.value("margin_voxels", f.margin_voxels);
  f.max_rays_per_view = j.value("max_rays_per_view", f.max_rays_per_view);
  f.hole_rays = j.value("hole_rays", f.hole_rays);
  f.hole_slack = j.value("hole_slack", f.hole_slack);
  return f;
}

// The GT objects, and every GT surface (stuff and objects) as one mesh with its caster.
absl::StatusOr<std::vector<GroundTruthObject>> ReadGroundTruth(const Scene& scene,
                                                               const CompletionEvalOptions& o,
                                                               TriangleMesh* everything,
                                                               std::unique_ptr<RayCaster>* caster) {
  if (!fs::exists(scene.Path("gt/meshes/stuff.ply"))) {
    return absl::FailedPreconditionError(absl::StrCat(
        scene.directory, ": gt/meshes/stuff.ply missing (regenerate the scene with synth)"));
  }
  ASSIGN_OR_RETURN(nlohmann::json objects, ReadJson(scene.Path("gt/objects.json")));
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

}  // namespace

namespace {

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
  std::vector<ObjectCompletionEval> results;
  std::unique_ptr<RayCaster> scene_caster;  // the scene's splats, read at the first hull closing
  for (const std::string& dir : dirs) {
    ObjectCompletionEval e;
    e.directory = dir;
    ASSIGN_OR_RETURN(nlohmann::json m, ReadJson((fs::path(dir) / "manifest.json").string()));
    ASSIGN_OR_RETURN(GaussianCloud object,
                     ReadGaussianPly((fs::path(dir) / "object.ply").string()));
    ASSIGN_OR_RETURN(TriangleMesh completed_mesh,
                     ReadMeshPly((fs::path(dir) / "mesh.ply").string()));
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
    // The ground-truth object most of the raw crop lies on.
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
    if (best == truth.size()) {
      results.push_back(e);  // nothing matched: reported with gt_id 0
      continue;
    }
    const GroundTruthObject& gt = truth[best];
    e.gt_id = gt.id;
    e.gt_name = gt.name;
    e.shape = gt.shape;
    size_t hidden = 0;
    for (uint8_t s : gt.seen) hidden += !s;
    e.hidden_share = static_cast<double>(hidden) / std::max<size_t>(1, gt.seen.size());
    MeshingOptions meshing;
    if (m.contains("meshing")) {
      meshing.size_px = m["meshing"].value("size_px", meshing.size_px);
      meshing.min_alpha = m["meshing"].value("min_alpha", meshing.min_alpha);
      // Manifests written before the inset meshed without it.
      meshing.inset_sigmas = m["meshing"].value("inset_sigmas", 0.0f);
      // And before the silhouette carving without it.
      meshing.carve_views = m["meshing"].value("carve_views", 0);
      meshing.empty_alpha = m["meshing"].value("empty_alpha", meshing.empty_alpha);
      meshing.empty_close_px = m["meshing"].value("empty_close_px", 0.0f);
      // And before the snap without it.
      meshing.snap_radius_spacings = m["meshing"].value("snap_radius_spacings", 0.0f);
      meshing.snap_layer_spacings =
          m["meshing"].value("snap_layer_spacings", meshing.snap_layer_spacings);
      meshing.snap_max_voxels = m["meshing"].value("snap_max_voxels", meshing.snap_max_voxels);
      meshing.snap_reach_spacings = m["meshing"].value("snap_reach_spacings", 0.0f);
      // And before the visual hull without it.
      meshing.enclose_hull = m["meshing"].value("enclose_hull", false);
      // And before the top clamp without it.
      meshing.top_at_highest_surfel = m["meshing"].value("top_at_highest_surfel", false);
      meshing.sides_within_surfels = m["meshing"].value("sides_within_surfels", false);
    }
    // The closed crop has no prior, so no rotation axis: its closing keeps the renders' visual hull
    // inside wherever the completion's would (completion.cc), against the same free space of the
    // capture (the scene's splats carved by the real views, as the completion carved it).
    std::function<bool(const Eigen::Vector3f&)> seen_empty;
    std::optional<FreeSpaceGrid> free_space;
    if (meshing.closed && meshing.enclose_hull) {
      if (scene_caster == nullptr) {
        ASSIGN_OR_RETURN(GaussianCloud cloud, ReadSceneGaussians(scene));
        cloud = ToSurfels(cloud);
        std::vector<uint32_t> everything(cloud.size());
        for (uint32_t g = 0; g < everything.size(); ++g) everything[g] = g;
        ASSIGN_OR_RETURN(scene_caster,
                         RayCaster::Create(SurfelDiscs(cloud, everything, SurfelDiscOptions{})));
      }
      ASSIGN_OR_RETURN(free_space, FreeSpaceGrid::Carve(cameras, *scene_caster, frame,
                                                        FreeSpaceFromManifest(m)));
      seen_empty = [&](const Eigen::Vector3f& p) { return free_space->IsFree(p); };
    }
    ASSIGN_OR_RETURN(TriangleMesh closed_mesh,
                     MeshObject(raw, frame, meshing, o.num_threads, seen_empty));
    const std::vector<Eigen::Vector3f> closed_points =
        SampleSurface(closed_mesh, o.samples, o.seed + 1);
    const std::vector<Eigen::Vector3f> completed_points =
        SampleSurface(completed_mesh, o.samples, o.seed + 2);
    e.raw = Geometry(raw_points, gt, o);
    e.closed = Geometry(closed_points, gt, o);
    e.completed = Geometry(completed_points, gt, o);
    // Volume IoU on one grid per object spanning the truth and all three versions.
    Eigen::AlignedBox3f box = gt.mesh.Bounds();
    for (const Eigen::Vector3f& p : raw_points) box.extend(p);
    box.extend(closed_mesh.Bounds());
    box.extend(completed_mesh.Bounds());
    box.extend(box.min() - 0.01f * box.sizes());
    box.extend(box.max() + 0.01f * box.sizes());
    const int r = o.volume_resolution;
    ASSIGN_OR_RETURN(const std::vector<uint8_t> truth_voxels, VoxelizeByRayParity(gt.mesh, box, r));
    ASSIGN_OR_RETURN(const std::vector<uint8_t> closed_voxels,
                     VoxelizeByRayParity(closed_mesh, box, r));
    ASSIGN_OR_RETURN(const std::vector<uint8_t> completed_voxels,
                     VoxelizeByRayParity(completed_mesh, box, r));
    e.raw.volume_iou = Iou(ShellVoxels(raw_points, box, r), truth_voxels);
    e.closed.volume_iou = Iou(closed_voxels, truth_voxels);
    e.completed.volume_iou = Iou(completed_voxels, truth_voxels);
    // Free space: completed surfels a real view saw through, away from every GT surface (a
    // surfel on a surface is no violation, whatever the pixel quantisation of the views).
    const float tolerance = static_cast<float>(0.01 * gt.diagonal);
    std::vector<Eigen::Vector3f> seen_through;
    for (uint32_t g : added) {
      const Eigen::Vector3f p(&object.positions[3 * g]);
      if (InObservedFreeSpace(p, cameras, *caster, tolerance)) seen_through.push_back(p);
    }
    for (float d : surfaces->Distances(seen_through)) {
      e.completed.free_space_violations += d > tolerance;
    }
    // Appearance at the ring views.
    const nlohmann::json& ring_json = m.at("ring");
    RingOptions ring;
    ring.views = static_cast<int>(ring_json.size());
    if (!ring_json.empty()) ring.elevation_deg = ring_json[0].value("elevation_deg", 30.0);
    if (m.contains("ring_camera")) {
      ring.size_px = m["ring_camera"].value("size_px", ring.size_px);
      ring.focal_px = m["ring_camera"].value("focal_px", ring.focal_px);
      ring.distance_radii = m["ring_camera"].value("distance_radii", ring.distance_radii);
    }
    std::vector<bool> known;
    for (const nlohmann::json& v : ring_json) {
      known.push_back(v.value("known", false));
      (known.back() ? e.known_views : e.unknown_views)++;
    }
    if (!gt.complete_surfels.empty()) {
      ASSIGN_OR_RETURN(GaussianCloud complete, ReadGaussianPly(scene.Path(gt.complete_surfels)));
      const std::vector<PinholeCamera> cameras_ring = RingCameras(frame, ring);
      ASSIGN_OR_RETURN(ViewScores raw_views,
                       ScoreViews(raw, complete, cameras_ring, known, frame, o.num_threads));
      ASSIGN_OR_RETURN(ViewScores done_views,
                       ScoreViews(object, complete, cameras_ring, known, frame, o.num_threads));
      for (VersionScores* v : {&e.raw, &e.closed}) {
        v->psnr_known = raw_views.psnr_known;
        v->psnr_unknown = raw_views.psnr_unknown;
        v->ssim_known = raw_views.ssim_known;
        v->ssim_unknown = raw_views.ssim_unknown;
      }
      e.completed.psnr_known = done_views.psnr_known;
      e.completed.psnr_unknown = done_views.psnr_unknown;
      e.completed.ssim_known = done_views.ssim_known;
      e.completed.ssim_unknown = done_views.ssim_unknown;
    }
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

nlohmann::json CompletionEvalJson(const std::vector<ObjectCompletionEval>& objects,
                                  const CompletionEvalOptions& o) {
  auto version = [&](const VersionScores& v) {
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
  };
  nlohmann::json list = nlohmann::json::array();
  std::map<std::string, std::vector<double>> sums;
  int matched = 0;
  for (const ObjectCompletionEval& e : objects) {
    list.push_back({{"id", e.id},
                    {"gt_id", e.gt_id},
                    {"gt_name", e.gt_name},
                    {"shape", e.shape},
                    {"abstained", e.abstained},
                    {"completed_share", e.completed_share},
                    {"hidden_share", e.hidden_share},
                    {"known_views", e.known_views},
                    {"unknown_views", e.unknown_views},
                    {"raw", version(e.raw)},
                    {"closed", version(e.closed)},
                    {"completed", version(e.completed)}});
    if (e.gt_id == 0) continue;
    ++matched;
    for (const auto& [name, v] :
         {std::pair{"raw", &e.raw}, {"closed", &e.closed}, {"completed", &e.completed}}) {
      auto& s = sums[name];
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
  return {{"objects", list},
          {"matched", matched},
          {"mean", mean},
          {"tau_fractions", o.tau_fractions},
          {"hidden_tau_fraction", o.hidden_tau_fraction}};
}

}  // namespace instascene::generation
