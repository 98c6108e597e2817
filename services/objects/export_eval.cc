#include "services/objects/export_eval.h"

#include <filesystem>
#include <optional>

#include <Eigen/Geometry>

#include "absl/strings/str_cat.h"
#include "common/core/json_file.h"
#include "common/core/status.h"
#include "common/eval/geometry_metrics.h"
#include "common/mesh/mesh_ply.h"
#include "common/scene/scene.h"

namespace instascene::objects {
namespace {
namespace fs = std::filesystem;
using nlohmann::json;

struct GtObject {
  uint32_t id = 0;
  std::string name;
  std::vector<Eigen::Vector3f> samples;   // metres, world
  std::vector<Eigen::Vector3f> vertices;  // metres, world
};

// The scene's ground-truth objects with meshes, in metres.
absl::StatusOr<std::vector<GtObject>> GroundTruthObjects(const Scene& scene,
                                                         const std::string& scene_dir, double mpu) {
  ASSIGN_OR_RETURN(json gt_list, ReadJsonFile(scene.Path("gt/objects.json"), 64 << 20));
  if (!gt_list.is_array())
    return absl::FailedPreconditionError(absl::StrCat(scene_dir, ": no ground truth objects"));
  std::vector<GtObject> gts;
  for (const json& o : gt_list) {
    if (!o.contains("mesh") || !o["mesh"].is_string()) continue;
    ASSIGN_OR_RETURN(TriangleMesh mesh, ReadMeshPly(scene.Path(o["mesh"].get<std::string>())));
    GtObject g;
    g.id = o.value("id", 0u);
    g.name = o.value("name", "");
    for (Eigen::Vector3f& v : mesh.vertices) v *= static_cast<float>(mpu);
    g.samples = SampleSurface(mesh, 4000, g.id);
    g.vertices = mesh.vertices;
    gts.push_back(std::move(g));
  }
  return gts;
}

// world_from_object of an export manifest.
Eigen::Isometry3d ManifestPose(const json& m) {
  const json& pose = m["world_from_object"];
  const json& q = pose["quaternion_xyzw"];
  const Eigen::Quaterniond rotation(q[3].get<double>(), q[0].get<double>(), q[1].get<double>(),
                                    q[2].get<double>());
  Eigen::Isometry3d out = Eigen::Isometry3d::Identity();
  out.linear() = rotation.normalized().toRotationMatrix();
  out.translation() =
      Eigen::Vector3d(pose["translation"][0].get<double>(), pose["translation"][1].get<double>(),
                      pose["translation"][2].get<double>());
  return out;
}

// One exported object against the ground-truth object nearest its placed mesh (Chamfer); its
// extents against that object's in the exported object's frame. nullopt without ground truth.
absl::StatusOr<std::optional<ExportObjectEval>> EvaluateOne(const std::string& dir,
                                                            const std::vector<GtObject>& gts) {
  ASSIGN_OR_RETURN(json m, ReadJsonFile(dir + "/manifest.json", 64 << 20));
  ASSIGN_OR_RETURN(TriangleMesh mesh, ReadMeshPly(dir + "/mesh.ply"));
  const Eigen::Isometry3d pose = ManifestPose(m);
  const Eigen::Matrix3d r = pose.linear();
  const Eigen::Vector3d t = pose.translation();
  TriangleMesh placed = mesh;
  for (Eigen::Vector3f& v : placed.vertices) v = (r * v.cast<double>() + t).cast<float>();
  const std::vector<Eigen::Vector3f> samples = SampleSurface(placed, 4000, 7);
  ExportObjectEval e;
  e.id = m.value("id", 0u);
  e.chamfer = std::numeric_limits<double>::infinity();
  const GtObject* best = nullptr;
  for (const GtObject& g : gts) {
    const double c = ComparePointClouds(samples, g.samples, 0.01).chamfer;
    if (c < e.chamfer) {
      e.chamfer = c;
      best = &g;
    }
  }
  if (best == nullptr) return std::nullopt;
  e.gt_id = best->id;
  e.gt_name = best->name;
  Eigen::AlignedBox3d gt_box, box;
  for (const Eigen::Vector3f& v : best->vertices)
    gt_box.extend(r.transpose() * (v.cast<double>() - t));
  for (const Eigen::Vector3f& v : mesh.vertices) box.extend(v.cast<double>());
  e.extent = box.sizes();
  e.gt_extent = gt_box.sizes();
  for (int a = 0; a < 3; ++a)
    e.extent_error = std::max(
        e.extent_error, std::abs(e.extent[a] - e.gt_extent[a]) / std::max(e.gt_extent[a], 1e-6));
  return e;
}

}  // namespace

absl::StatusOr<std::vector<ExportObjectEval>> EvaluateExport(const std::string& scene_dir,
                                                             const std::string& export_dir) {
  ASSIGN_OR_RETURN(Scene scene, ReadScene(scene_dir));
  if (!scene.meters_per_unit)
    return absl::FailedPreconditionError(absl::StrCat(scene_dir, ": no meters_per_unit"));
  ASSIGN_OR_RETURN(const std::vector<GtObject> gts,
                   GroundTruthObjects(scene, scene_dir, *scene.meters_per_unit));
  ASSIGN_OR_RETURN(json catalogue,
                   ReadJsonFile((fs::path(export_dir) / "objects.json").string(), 64 << 20));
  std::vector<ExportObjectEval> out;
  for (const json& entry : catalogue.value("objects", json::array())) {
    ASSIGN_OR_RETURN(std::optional<ExportObjectEval> e,
                     EvaluateOne((fs::path(export_dir) / entry.value("dir", "")).string(), gts));
    if (e) out.push_back(*e);
  }
  return out;
}

json ExportEvalJson(const std::vector<ExportObjectEval>& evals) {
  json objects = json::array();
  double chamfer = 0, extent = 0;
  int within = 0;
  for (const ExportObjectEval& e : evals) {
    objects.push_back({{"id", e.id},
                       {"gt_id", e.gt_id},
                       {"gt_name", e.gt_name},
                       {"extent_m", {e.extent.x(), e.extent.y(), e.extent.z()}},
                       {"gt_extent_m", {e.gt_extent.x(), e.gt_extent.y(), e.gt_extent.z()}},
                       {"extent_error", e.extent_error},
                       {"chamfer_m", e.chamfer}});
    chamfer += e.chamfer;
    extent += e.extent_error;
    within += e.extent_error <= 0.05;
  }
  const double n = std::max<size_t>(evals.size(), 1);
  return {{"objects", objects},
          {"mean", {{"extent_error", extent / n}, {"chamfer_m", chamfer / n}}},
          {"extents_within_5_percent", within},
          {"count", evals.size()}};
}

}  // namespace instascene::objects
