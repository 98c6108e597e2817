#include "services/generation/stage.h"

#include <filesystem>

#include <nlohmann/json.hpp>

#include "absl/strings/str_cat.h"
#include "common/core/file_io.h"
#include "common/core/status.h"
#include "common/eval/result.h"
#include "common/scene/image_io.h"
#include "common/scene/scene.h"
#include "services/generation/completion.h"
#include "services/generation/stage_params.h"
#include "services/pipeline/memory.h"

namespace instascene::generation {
namespace {

// The instance id of item `item` of a segment output: instances.json lists them in id order.
absl::StatusOr<uint32_t> InstanceOfItem(const std::string& segment_dir, int64_t item) {
  const std::string path = (std::filesystem::path(segment_dir) / "instances.json").string();
  ASSIGN_OR_RETURN(std::string text, ReadFileBounded(path, 64 << 20));
  const nlohmann::json instances = nlohmann::json::parse(text, nullptr, false);
  if (!instances.is_array()) return absl::DataLossError(absl::StrCat(path, ": not a JSON array"));
  if (item < 0 || item >= static_cast<int64_t>(instances.size())) {
    return absl::OutOfRangeError(
        absl::StrCat("item ", item, " outside the ", instances.size(), " instances of ", path));
  }
  const nlohmann::json& entry = instances[item];
  if (!entry.is_object() || !entry.contains("id") || !entry["id"].is_number_unsigned()) {
    return absl::DataLossError(absl::StrCat(path, ": entry ", item, " has no id"));
  }
  return entry["id"].get<uint32_t>();
}

}  // namespace

CompletionOptions ToCompletionOptions(const CompleteStageOptions& o) {
  CompletionOptions options;
  options.prior = o.prior;
  options.ring.views = o.ring_views;
  options.ring.elevation_deg = o.ring_elevation;
  options.ring.size_px = o.ring_size;
  options.ring.focal_px = 280.0 * o.ring_size / 256.0;
  options.top_training_views = o.top_training_views;
  options.free_space.resolution = o.free_space_resolution;
  options.geometric.symmetry.min_agreement = o.min_agreement;
  options.geometric.symmetry.min_plane_agreement = o.min_plane_agreement;
  options.meshing.size_px = o.mesh_size;
  options.meshing.min_alpha = static_cast<float>(o.mesh_min_alpha);
  options.meshing.inset_sigmas = static_cast<float>(o.mesh_inset_sigmas);
  options.meshing.carve_views = o.mesh_carve_views;
  options.meshing.cull_inner_sides = o.mesh_cull_inner_sides;
  options.meshing.enclose_hull = o.mesh_enclose_hull;
  options.meshing.snap_radius_spacings = static_cast<float>(o.mesh_snap_spacings);
  options.min_gaussians = static_cast<size_t>(o.min_gaussians);
  options.seed = o.seed;
  options.refinement.iterations = o.refine_iterations;
  options.refinement.lambda_normal = o.refine_lambda_normal;
  options.refine_view_max_side = o.refine_view_size;
  options.diffusion.replace_fraction = o.diffusion_replace_fraction;
  options.diffusion.warp = o.diffusion_warp;
  options.diffusion.unseen_mask = o.diffusion_unseen_mask;
  return options;
}

namespace {

absl::StatusOr<pipeline::StageResult> RunComplete(const pipeline::StageContext& c) {
  ASSIGN_OR_RETURN(CompleteStageOptions o, CompleteCodec().Decode(c.parameters));
  auto denoiser = c.settings.find("denoiser");
  if (o.prior == "diffusion" && denoiser == c.settings.end()) {
    return absl::FailedPreconditionError(
        "prior diffusion: this worker has no denoiser (start it with --denoiser "
        "grpc://HOST:PORT or onnx:FILE.json)");
  }
  ASSIGN_OR_RETURN(std::string segment, c.Input("segment"));
  ASSIGN_OR_RETURN(uint32_t id, InstanceOfItem(segment, c.item));
  CompletionOptions options = ToCompletionOptions(o);
  options.num_threads = c.num_threads;
  options.cancel = c.cancel;
  if (denoiser != c.settings.end()) options.denoiser = denoiser->second;
  c.Report("loading", 0, 1);
  ASSIGN_OR_RETURN(Scene scene, ReadScene(c.scene_dir));
  ASSIGN_OR_RETURN(GaussianCloud cloud, ReadSceneGaussians(scene));
  cloud = ToSurfels(cloud);
  ASSIGN_OR_RETURN(SegmentationResult result, ReadResult(segment, cloud.size()));
  std::vector<PinholeCamera> cameras;
  for (const SceneView& view : scene.views) cameras.push_back(view.camera);
  options.load_view = [&scene](int view) { return ReadViewImage(scene, view); };
  ASSIGN_OR_RETURN(CompletedObject object,
                   CompleteObject(cameras, cloud, result.labels, id, options,
                                  [&](const std::string& phase, int step, int total) {
                                    c.Report(absl::StrCat("object ", id, ": ", phase), step, total);
                                  }));
  RETURN_IF_ERROR(CheckCancelled(c.cancel, "complete"));
  RETURN_IF_ERROR(WriteCompletedObject(c.out_dir, object, c.num_threads));
  return pipeline::StageResult{};
}

// The whole splat (the occluders) with its Embree scene, the free-space grid, the ring's
// renders (colour, depth, alpha, normals, traces), the meshing views with their fusion volume and,
// when refining, the cropped real views with their traces and the optimiser state.
absl::StatusOr<int64_t> EstimateComplete(const pipeline::StageContext& c) {
  ASSIGN_OR_RETURN(CompleteStageOptions o, CompleteCodec().Decode(c.parameters));
  ASSIGN_OR_RETURN(pipeline::SceneFootprint f, pipeline::ReadSceneFootprint(c.scene_dir));
  const int64_t grid =
      int64_t{o.free_space_resolution} * o.free_space_resolution * o.free_space_resolution;
  const int64_t ring = int64_t{o.ring_views} * o.ring_size * o.ring_size;
  const int64_t mesh = int64_t{o.ring_views} * o.mesh_size * o.mesh_size;
  int64_t bytes = 160 * pipeline::kMiB + 720 * f.gaussians + 16 * grid + 96 * ring + 64 * mesh +
                  12 * f.total_pixels;
  if (o.refine_iterations > 0)
    bytes += int64_t{o.top_training_views + o.ring_views} * o.refine_view_size *
                 o.refine_view_size * 512 +
             160 * f.gaussians;
  return bytes;
}

}  // namespace

pipeline::StageDefinition CompleteStage() {
  return {CompleteSpec(), RunComplete, EstimateComplete};
}

}  // namespace instascene::generation
