#include "services/pipeline/stages.h"

#include <filesystem>

#include "absl/strings/str_cat.h"
#include "common/core/status.h"
#include "common/eval/result.h"
#include "common/scene/scene.h"
#include "services/decomposition/decompose.h"
#include "services/training/feature_field.h"
#include "services/training/segmentation.h"
#include "services/training/vote.h"

namespace instascene::pipeline {
namespace {

// Reads parameter `name` of type T into *out if present; type errors name stage and key.
template <typename T>
absl::Status Read(const nlohmann::json& p, const std::string& kind, const char* name, T* out) {
  if (!p.contains(name)) return absl::OkStatus();
  const nlohmann::json& v = p[name];
  bool ok = false;
  if constexpr (std::is_same_v<T, bool>) {
    ok = v.is_boolean();
  } else if constexpr (std::is_integral_v<T>) {
    ok = v.is_number_integer();
  } else if constexpr (std::is_floating_point_v<T>) {
    ok = v.is_number();
  } else {
    ok = v.is_string();
  }
  if (!ok)
    return absl::InvalidArgumentError(absl::StrCat("stage ", kind, ": parameter '", name,
                                                   "' has the wrong type (", v.dump(), ")"));
  *out = v.get<T>();
  return absl::OkStatus();
}

absl::Status OnlyKnownKeys(const nlohmann::json& p, const std::string& kind,
                           std::initializer_list<const char*> known) {
  if (!p.is_object())
    return absl::InvalidArgumentError(
        absl::StrCat("stage ", kind, ": parameters must be an object"));
  for (const auto& [key, value] : p.items()) {
    bool found = false;
    for (const char* k : known) found |= key == k;
    if (!found)
      return absl::InvalidArgumentError(
          absl::StrCat("stage ", kind, ": unknown parameter '", key, "'"));
  }
  return absl::OkStatus();
}

absl::StatusOr<decomposition::DecompositionOptions> DecomposeOptions(const nlohmann::json& p) {
  RETURN_IF_ERROR(OnlyKnownKeys(p, "decompose",
                                {"tracker_min_weight", "dbscan_eps", "dbscan_eps_relative",
                                 "view_consensus_threshold", "min_tracker_gaussians"}));
  decomposition::DecompositionOptions o;
  RETURN_IF_ERROR(Read(p, "decompose", "tracker_min_weight", &o.tracker_min_weight));
  RETURN_IF_ERROR(Read(p, "decompose", "dbscan_eps", &o.dbscan_eps));
  RETURN_IF_ERROR(Read(p, "decompose", "dbscan_eps_relative", &o.dbscan_eps_relative));
  RETURN_IF_ERROR(Read(p, "decompose", "view_consensus_threshold", &o.view_consensus_threshold));
  RETURN_IF_ERROR(Read(p, "decompose", "min_tracker_gaussians", &o.min_tracker_gaussians));
  RETURN_IF_ERROR(Annotate(o.Validate(), "stage decompose"));
  return o;
}

struct TrainParameters {
  training::TrainingOptions options;
  std::string supervision = "full", method = "contrastive";
};

absl::StatusOr<TrainParameters> TrainOptions(const nlohmann::json& p) {
  RETURN_IF_ERROR(OnlyKnownKeys(
      p, "train", {"iterations", "samples", "pixel_pool", "supervision", "method", "seed"}));
  TrainParameters t;
  RETURN_IF_ERROR(Read(p, "train", "iterations", &t.options.iterations));
  RETURN_IF_ERROR(Read(p, "train", "samples", &t.options.samples));
  RETURN_IF_ERROR(Read(p, "train", "pixel_pool", &t.options.pixel_pool));
  RETURN_IF_ERROR(Read(p, "train", "supervision", &t.supervision));
  RETURN_IF_ERROR(Read(p, "train", "method", &t.method));
  RETURN_IF_ERROR(Read(p, "train", "seed", &t.options.seed));
  if (t.options.iterations < 1 || t.options.samples < 1 || t.options.pixel_pool < 1)
    return absl::InvalidArgumentError(
        "stage train: iterations, samples and pixel_pool must be >= 1");
  if (t.method != "contrastive" && t.method != "vote")
    return absl::InvalidArgumentError(
        absl::StrCat("stage train: method '", t.method, "' is not contrastive or vote"));
  absl::StatusOr<training::Supervision> supervision = training::ParseSupervision(t.supervision);
  if (!supervision.ok()) return Annotate(supervision.status(), "stage train");
  t.options.supervision = *supervision;
  RETURN_IF_ERROR(Annotate(t.options.Validate(), "stage train"));
  return t;
}

absl::StatusOr<double> SegmentThreshold(const nlohmann::json& p) {
  RETURN_IF_ERROR(OnlyKnownKeys(p, "segment", {"threshold"}));
  double threshold = 0.9;
  RETURN_IF_ERROR(Read(p, "segment", "threshold", &threshold));
  if (!(threshold > -1.0 && threshold <= 1.0))
    return absl::InvalidArgumentError(
        absl::StrCat("stage segment: threshold ", threshold, " is not in (-1, 1]"));
  return threshold;
}

void Report(const StageContext& c, const std::string& phase, int64_t step, int64_t total,
            double loss = 0) {
  if (c.progress) c.progress(StageProgress{phase, step, total, loss});
}

absl::Status RunDecompose(const StageContext& c, const Scene& scene, const GaussianCloud& cloud) {
  ASSIGN_OR_RETURN(decomposition::DecompositionOptions options, DecomposeOptions(c.parameters));
  options.num_threads = c.num_threads;
  options.cancel = c.cancel;
  ASSIGN_OR_RETURN(decomposition::DecompositionResult result,
                   decomposition::Decompose(scene, cloud, options,
                                            [&](const std::string& phase, int done, int total) {
                                              Report(c, phase, done, total);
                                            }));
  RETURN_IF_ERROR(CheckCancelled(c.cancel, "decompose"));
  Report(c, "writing", 0, 1);
  return decomposition::WriteDecomposition(c.out_dir, scene, cloud, result);
}

absl::Status RunTrain(const StageContext& c, const Scene& scene, const GaussianCloud& cloud) {
  ASSIGN_OR_RETURN(TrainParameters t, TrainOptions(c.parameters));
  t.options.num_threads = c.num_threads;
  t.options.cancel = c.cancel;
  SegmentationResult result;
  if (t.method == "vote") {
    result.stage = "vote";
    ASSIGN_OR_RETURN(result.labels, training::VoteLabels(scene, cloud, c.input_dir, c.num_threads));
  } else {
    ASSIGN_OR_RETURN(
        training::TrainingData data,
        training::PrepareTraining(scene, cloud, c.input_dir, t.options, [&](int done, int total) {
          Report(c, "tracing pixel pools", done, total);
        }));
    ASSIGN_OR_RETURN(
        training::TrainingResult trained,
        training::TrainFeatures(data, t.options, [&](int step, int total, double loss) {
          if (step % 10 == 0 || step == total) Report(c, "training", step, total, loss);
        }));
    // Coarse labels with the features: the segment stage applies the tau rule to them.
    result.stage = "train";
    result.labels = data.labels3d;
    result.features = std::move(trained.features);
    result.feature_dim = t.options.feature_dim;
    result.metadata["supervision"] = t.supervision;
    result.metadata["iterations"] = t.options.iterations;
    result.metadata["final_loss"] = trained.loss.empty() ? 0.0 : trained.loss.back();
    result.metadata["train_seconds"] = trained.seconds;
  }
  Report(c, "writing", 0, 1);
  return WriteResult(c.out_dir, result, cloud);
}

absl::Status RunSegment(const StageContext& c, const GaussianCloud& cloud) {
  ASSIGN_OR_RETURN(double threshold, SegmentThreshold(c.parameters));
  ASSIGN_OR_RETURN(SegmentationResult in, ReadResult(c.input_dir, cloud.size()));
  SegmentationResult out = in;
  out.stage = "segment";
  if (in.feature_dim > 0) {
    out.labels = training::SegmentByFeatures(in.features, in.feature_dim, in.labels,
                                             training::SegmentOptions{threshold});
  }
  out.metadata["threshold"] = threshold;
  Report(c, "exporting", 0, 1);
  RETURN_IF_ERROR(WriteResult(c.out_dir, out, cloud));
  return training::ExportInstances(c.out_dir, cloud, out.labels);
}

}  // namespace

const std::vector<std::string>& DefaultStages() {
  static const std::vector<std::string> stages = {"decompose", "train", "segment"};
  return stages;
}

absl::StatusOr<std::string> StageInput(const std::string& kind) {
  if (kind == "decompose") return std::string();
  if (kind == "train") return std::string("decompose");
  if (kind == "segment") return std::string("train");
  return absl::InvalidArgumentError(
      absl::StrCat("unknown stage '", kind, "' (decompose, train, segment)"));
}

absl::Status ValidateParameters(const std::string& kind, const nlohmann::json& parameters) {
  RETURN_IF_ERROR(StageInput(kind).status());
  if (kind == "decompose") return DecomposeOptions(parameters).status();
  if (kind == "train") return TrainOptions(parameters).status();
  return SegmentThreshold(parameters).status();
}

absl::Status RunStage(const std::string& kind, const StageContext& c) {
  RETURN_IF_ERROR(ValidateParameters(kind, c.parameters));
  Report(c, "loading", 0, 1);
  ASSIGN_OR_RETURN(Scene scene, ReadScene(c.scene_dir));
  ASSIGN_OR_RETURN(GaussianCloud cloud, ReadSceneGaussians(scene));
  RETURN_IF_ERROR(CheckCancelled(c.cancel, kind));
  if (kind == "decompose") return RunDecompose(c, scene, cloud);
  if (kind == "train") return RunTrain(c, scene, cloud);
  return RunSegment(c, cloud);
}

}  // namespace instascene::pipeline
