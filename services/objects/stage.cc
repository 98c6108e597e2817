#include "services/objects/stage.h"

#include <filesystem>

#include <nlohmann/json.hpp>

#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "common/core/file_io.h"
#include "common/core/status.h"
#include "common/scene/scene.h"
#include "services/objects/export.h"
#include "services/pipeline/memory.h"

namespace instascene::objects {
namespace {
namespace fs = std::filesystem;

absl::StatusOr<pipeline::StageResult> RunExport(const pipeline::StageContext& c) {
  ASSIGN_OR_RETURN(ExportStageOptions o, ExportCodec().Decode(c.parameters));
  ExportOptions options;
  options.density = o.density;
  options.surface_points = o.surface_points;
  options.decomposition.max_parts = o.collision_parts;
  options.decomposition.resolution = o.collision_resolution;
  options.seed = o.seed;
  ASSIGN_OR_RETURN(Scene scene, ReadScene(c.scene_dir));
  MetricScale scale{scene.meters_per_unit, "scene.json meters_per_unit"};
  // The completed objects, in item order; items whose completion failed are absent (partial join).
  const std::vector<std::string> objects = c.AllInputs("complete");
  nlohmann::json catalogue = nlohmann::json::array();
  for (size_t i = 0; i < objects.size(); ++i) {
    RETURN_IF_ERROR(CheckCancelled(c.cancel, "export"));
    c.Report("export", static_cast<int>(i), static_cast<int>(objects.size()));
    ASSIGN_OR_RETURN(std::string text,
                     ReadFileBounded((fs::path(objects[i]) / "manifest.json").string(), 64 << 20));
    const nlohmann::json in = nlohmann::json::parse(text, nullptr, false);
    if (!in.is_object() || !in.contains("id") || !in["id"].is_number_unsigned())
      return absl::DataLossError(absl::StrCat("complete/", i, "/manifest.json: no object id"));
    const std::string id = std::to_string(in["id"].get<uint32_t>());
    ASSIGN_OR_RETURN(nlohmann::json m,
                     ExportObject(objects[i], scale, options, (fs::path(c.out_dir) / id).string()));
    catalogue.push_back({{"id", m["id"]},
                         {"dir", id},
                         {"units", m["units"]},
                         {"world_from_object", m["world_from_object"]},
                         {"extent", m["bounding_box"]["extent"]},
                         {"completion", m["completion"]},
                         {"completed_share", m["completed_share"]},
                         {"collision_parts", m["collision"]["parts"].size()},
                         {"mass", m["inertial"]["mass"]}});
  }
  c.Report("export", static_cast<int>(objects.size()), static_cast<int>(objects.size()));
  RETURN_IF_ERROR(WriteFileAtomically(
      (fs::path(c.out_dir) / "objects.json").string(),
      nlohmann::json({{"format", "instascene.objects/1"}, {"objects", catalogue}}).dump(1)));
  return pipeline::StageResult{};
}

// The object's splat and mesh (bounded by the scene's splat), its voxelisation for the convex
// decomposition (per part) and the surface samples.
absl::StatusOr<int64_t> EstimateExport(const pipeline::StageContext& c) {
  ASSIGN_OR_RETURN(ExportStageOptions o, ExportCodec().Decode(c.parameters));
  ASSIGN_OR_RETURN(pipeline::SceneFootprint f, pipeline::ReadSceneFootprint(c.scene_dir));
  const int64_t voxels =
      int64_t{o.collision_resolution} * o.collision_resolution * o.collision_resolution;
  return 96 * pipeline::kMiB + 400 * f.gaussians + 64 * voxels * (1 + o.collision_parts) +
         64 * int64_t{o.surface_points};
}

}  // namespace

pipeline::StageDefinition ExportStage() { return {ExportSpec(), RunExport, EstimateExport}; }

}  // namespace instascene::objects
