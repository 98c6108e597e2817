#include "services/decomposition/stage.h"

#include "common/core/status.h"
#include "common/scene/scene.h"
#include "services/decomposition/decompose.h"
#include "services/decomposition/stage_params.h"

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

}  // namespace

pipeline::StageDefinition DecomposeStage() { return {DecomposeSpec(), RunDecompose}; }

}  // namespace instascene::decomposition
