#include "services/decomposition/stage.h"

#include "common/core/status.h"
#include "common/scene/scene.h"
#include "services/decomposition/decompose.h"
#include "services/decomposition/stage_params.h"
#include "services/pipeline/memory.h"

namespace instascene::decomposition {
namespace {

absl::StatusOr<pipeline::StageResult> RunDecompose(const pipeline::StageContext& c) {
  ASSIGN_OR_RETURN(DecompositionOptions options, DecomposeCodec().Decode(c.parameters));
  options.num_threads = c.num_threads;
  options.cancel = c.cancel;
  c.Report("loading", 0, 1);
  ASSIGN_OR_RETURN(Scene scene, ReadScene(c.scene_dir));
  ASSIGN_OR_RETURN(GaussianCloud cloud, ReadSceneGaussians(scene));
  RETURN_IF_ERROR(CheckCancelled(c.cancel, "decompose"));
  ASSIGN_OR_RETURN(
      DecompositionResult result,
      Decompose(scene, cloud, options, [&](const std::string& phase, int done, int total) {
        c.Report(phase, done, total);
      }));
  RETURN_IF_ERROR(CheckCancelled(c.cancel, "decompose"));
  c.Report("writing", 0, 1);
  RETURN_IF_ERROR(WriteDecomposition(c.out_dir, scene, cloud, result));
  return pipeline::StageResult{};
}

// The splat (~240 B per Gaussian with its SH), per Gaussian and view its mask votes, every view's
// label map and the traces of the views rasterised at once (docs/RELIABILITY.md "Memory
// estimates").
absl::StatusOr<int64_t> EstimateDecompose(const pipeline::StageContext& c) {
  ASSIGN_OR_RETURN(pipeline::SceneFootprint f, pipeline::ReadSceneFootprint(c.scene_dir));
  return 64 * pipeline::kMiB + 320 * f.gaussians + 6 * f.gaussians * f.views + 12 * f.total_pixels +
         256 * f.max_view_pixels;
}

}  // namespace

pipeline::StageDefinition DecomposeStage() {
  return {DecomposeSpec(), RunDecompose, EstimateDecompose};
}

}  // namespace instascene::decomposition
