#include "services/training/stage.h"

#include <set>

#include "common/core/status.h"
#include "common/eval/result.h"
#include "common/scene/scene.h"
#include "services/pipeline/memory.h"
#include "services/training/feature_field.h"
#include "services/training/segmentation.h"
#include "services/training/stage_params.h"
#include "services/training/vote.h"

namespace instascene::training {
namespace {

absl::StatusOr<pipeline::StageResult> RunTrain(const pipeline::StageContext& c) {
  ASSIGN_OR_RETURN(TrainStageOptions o, TrainCodec().Decode(c.parameters));
  ASSIGN_OR_RETURN(std::string decomposition, c.Input("decompose"));
  TrainingOptions options = o;
  options.num_threads = c.num_threads;
  options.cancel = c.cancel;
  c.Report("loading", 0, 1);
  ASSIGN_OR_RETURN(Scene scene, ReadScene(c.scene_dir));
  ASSIGN_OR_RETURN(GaussianCloud cloud, ReadSceneGaussians(scene));
  SegmentationResult result;
  if (o.method == "vote") {
    result.stage = "vote";
    ASSIGN_OR_RETURN(result.labels, VoteLabels(scene, cloud, decomposition, c.num_threads));
  } else {
    ASSIGN_OR_RETURN(
        TrainingData data,
        PrepareTraining(scene, cloud, decomposition, options, [&](int done, int total) {
          c.Report("tracing pixel pools", done, total);
        }));
    ASSIGN_OR_RETURN(TrainingResult trained,
                     TrainFeatures(data, options, [&](int step, int total, double loss) {
                       if (step % 10 == 0 || step == total) c.Report("training", step, total, loss);
                     }));
    // Coarse labels with the features: the segment stage applies the tau rule to them.
    result.stage = "train";
    result.labels = data.labels3d;
    result.features = std::move(trained.features);
    result.feature_dim = options.feature_dim;
    result.metadata["supervision"] = c.parameters.value("supervision", "full");
    result.metadata["iterations"] = options.iterations;
    result.metadata["final_loss"] = trained.loss.empty() ? 0.0 : trained.loss.back();
    result.metadata["train_seconds"] = trained.seconds;
  }
  RETURN_IF_ERROR(CheckCancelled(c.cancel, "train"));
  c.Report("writing", 0, 1);
  RETURN_IF_ERROR(WriteResult(c.out_dir, result, cloud));
  return pipeline::StageResult{};
}

absl::StatusOr<pipeline::StageResult> RunSegment(const pipeline::StageContext& c) {
  ASSIGN_OR_RETURN(SegmentStageOptions o, SegmentCodec().Decode(c.parameters));
  ASSIGN_OR_RETURN(std::string trained, c.Input("train"));
  c.Report("loading", 0, 1);
  ASSIGN_OR_RETURN(Scene scene, ReadScene(c.scene_dir));
  ASSIGN_OR_RETURN(GaussianCloud cloud, ReadSceneGaussians(scene));
  ASSIGN_OR_RETURN(SegmentationResult in, ReadResult(trained, cloud.size()));
  SegmentationResult out = in;
  out.stage = "segment";
  ASSIGN_OR_RETURN(out.labels, FinalLabels(in, cloud, o, c.num_threads, &out.metadata));
  c.Report("exporting", 0, 1);
  RETURN_IF_ERROR(WriteResult(c.out_dir, out, cloud));
  RETURN_IF_ERROR(ExportInstances(c.out_dir, cloud, out.labels));
  std::set<uint32_t> instances(out.labels.begin(), out.labels.end());
  instances.erase(0);
  return pipeline::StageResult{static_cast<int64_t>(instances.size())};
}

// The splat, the feature field with its gradient and Adam moments (4 x D floats per Gaussian),
// the traced pixel pool of every view (contributors with weights) and the label maps.
absl::StatusOr<int64_t> EstimateTrain(const pipeline::StageContext& c) {
  ASSIGN_OR_RETURN(TrainStageOptions o, TrainCodec().Decode(c.parameters));
  ASSIGN_OR_RETURN(pipeline::SceneFootprint f, pipeline::ReadSceneFootprint(c.scene_dir));
  const int64_t pool = std::min<int64_t>(o.pixel_pool, f.max_view_pixels);
  return 96 * pipeline::kMiB + 320 * f.gaussians + 16 * int64_t{o.feature_dim} * f.gaussians +
         f.views * pool * 512 + 12 * f.total_pixels + int64_t{o.samples} * o.feature_dim * 64;
}

// The splat with its features and labels; HDBSCAN works on at most max_points voxels.
absl::StatusOr<int64_t> EstimateSegment(const pipeline::StageContext& c) {
  ASSIGN_OR_RETURN(pipeline::SceneFootprint f, pipeline::ReadSceneFootprint(c.scene_dir));
  return 64 * pipeline::kMiB + 512 * f.gaussians;
}

}  // namespace

pipeline::StageDefinition TrainStage() { return {TrainSpec(), RunTrain, EstimateTrain}; }
pipeline::StageDefinition SegmentStage() { return {SegmentSpec(), RunSegment, EstimateSegment}; }

}  // namespace instascene::training
