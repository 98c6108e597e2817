// `instascene train`, `instascene segment` and `instascene run` (decompose + train + segment).
#include <cstdio>
#include <filesystem>

#include <nlohmann/json.hpp>

#include "clients/cli/cli.h"
#include "clients/cli/progress.h"
#include "clients/cli/stage_flags.h"
#include "common/core/status.h"
#include "common/core/timer.h"
#include "common/eval/result.h"
#include "services/decomposition/stage_params.h"
#include "services/pipeline/local_runner.h"
#include "services/stages/all_stages.h"
#include "services/training/feature_field.h"
#include "services/training/segmentation.h"
#include "services/training/stage_params.h"
#include "services/training/vote.h"

#include <map>
#include <set>

namespace instascene::cli {
namespace {

struct TrainArgs {
  std::string scene, decomposition, out;
  std::vector<std::string> stages;  // run: a subset of the pipeline (empty = all)
  StageFlags flags;                 // the stages' parameters, from their codecs
  int threads = 0;
  bool json = false;
};

void AddCommonOptions(CLI::App* cmd, TrainArgs* args) {
  cmd->add_option("--threads", args->threads, "Threads (0 = all cores)");
  cmd->add_flag("--json", args->json, "Print a JSON summary as the last stdout line");
}

// The training-free baseline (`--method vote`): labels by weighted 2D-mask voting.
absl::Status VoteAndWrite(const TrainArgs& args, const Scene& scene, const GaussianCloud& cloud,
                          const std::string& decomposition_dir, nlohmann::json* summary) {
  Stopwatch watch;
  SegmentationResult result;
  result.stage = "vote";
  ASSIGN_OR_RETURN(result.labels,
                   training::VoteLabels(scene, cloud, decomposition_dir, args.threads));
  RETURN_IF_ERROR(WriteResult(args.out, result, cloud));
  RETURN_IF_ERROR(training::ExportInstances(args.out, cloud, result.labels));
  std::fprintf(stderr, "vote: labels by weighted 2D-mask voting in %.1f s; wrote %s\n",
               watch.ElapsedSeconds(), args.out.c_str());
  (*summary)["out"] = args.out;
  return absl::OkStatus();
}

// Trains on a decomposition and writes the segmented result (result format + instances).
absl::Status TrainAndSegment(const TrainArgs& args, const Scene& scene, const GaussianCloud& cloud,
                             const std::string& decomposition_dir, nlohmann::json* summary) {
  ASSIGN_OR_RETURN(nlohmann::json parameters, args.flags.Parameters());
  ASSIGN_OR_RETURN(
      training::TrainStageOptions train,
      training::TrainCodec().Decode(parameters.value("train", nlohmann::json::object())));
  ASSIGN_OR_RETURN(
      training::SegmentStageOptions segment,
      training::SegmentCodec().Decode(parameters.value("segment", nlohmann::json::object())));
  train.num_threads = args.threads;
  if (train.method == "vote") return VoteAndWrite(args, scene, cloud, decomposition_dir, summary);
  const training::TrainingOptions& options = train;
  ProgressBar prepare_bar("train: tracing pixel pools");
  ASSIGN_OR_RETURN(
      training::TrainingData data,
      training::PrepareTraining(scene, cloud, decomposition_dir, options,
                                [&](int done, int total) { prepare_bar.Update(done, total); }));
  ProgressBar bar("train: steps");
  ASSIGN_OR_RETURN(training::TrainingResult trained,
                   training::TrainFeatures(data, options, [&](int step, int total, double) {
                     if (step % 25 == 0 || step == total) bar.Update(step, total);
                   }));
  SegmentationResult result;
  result.stage = "segment";
  result.labels = data.labels3d;  // the coarse instances the labelling starts from
  result.features = trained.features;
  result.feature_dim = options.feature_dim;
  ASSIGN_OR_RETURN(result.labels,
                   training::FinalLabels(result, cloud, segment, args.threads, &result.metadata));
  result.metadata["supervision"] = training::TrainCodec().Encode(train)["supervision"];
  result.metadata["iterations"] = options.iterations;
  RETURN_IF_ERROR(WriteResult(args.out, result, cloud));
  RETURN_IF_ERROR(training::ExportInstances(args.out, cloud, result.labels));
  size_t labelled = 0;
  for (uint32_t l : result.labels) labelled += l != 0;
  std::fprintf(
      stderr,
      "train: %d steps in %.1f s (final loss %.3g); %zu of %zu Gaussians labelled; wrote %s\n",
      options.iterations, trained.seconds, trained.loss.empty() ? 0.0 : trained.loss.back(),
      labelled, cloud.size(), args.out.c_str());
  (*summary)["train_s"] = trained.seconds;
  (*summary)["labelled"] = labelled;
  (*summary)["out"] = args.out;
  return absl::OkStatus();
}

// `train`: trains the feature field on a decomposition, then segments.
void AddTrainCommand(CLI::App& app, Action* action) {
  auto train = std::make_shared<TrainArgs>();
  CLI::App* cmd = app.add_subcommand(
      "train", "Train the spatial contrastive feature field on a decomposition, then segment");
  cmd->add_option("--scene", train->scene, "Scene directory")->required();
  cmd->add_option("--decomposition", train->decomposition, "Output of instascene decompose")
      ->required();
  cmd->add_option("--out", train->out, "Result directory (features, labels, instances/*.ply)")
      ->required();
  train->flags.Add(cmd, training::TrainSpec());
  train->flags.Add(cmd, training::SegmentSpec());
  AddCommonOptions(cmd, train.get());
  cmd->callback([train, action] {
    *action = [train]() -> absl::Status {
      ASSIGN_OR_RETURN(Scene scene, ReadScene(train->scene));
      ASSIGN_OR_RETURN(GaussianCloud cloud, ReadSceneGaussians(scene));
      nlohmann::json summary;
      RETURN_IF_ERROR(TrainAndSegment(*train, scene, cloud, train->decomposition, &summary));
      if (train->json) PrintJsonLine(summary.dump());
      return absl::OkStatus();
    };
  });
}

// `segment`: labels trained features again (tau rule or HDBSCAN).
void AddSegmentCommand(CLI::App& app, Action* action) {
  struct SegmentArgs {
    std::string scene, features, decomposition, out;
    StageFlags flags;
  };
  auto segment = std::make_shared<SegmentArgs>();
  CLI::App* seg = app.add_subcommand(
      "segment",
      "Re-segment trained features (instances from their coarse labels: tau rule or HDBSCAN)");
  seg->add_option("--scene", segment->scene, "Scene directory")->required();
  seg->add_option("--features", segment->features,
                  "A result directory with features: `run`'s training/ (its labels are the coarse "
                  "instances) or `instascene train`'s output (give --decomposition too: its labels "
                  "are already final)")
      ->required();
  seg->add_option("--decomposition", segment->decomposition,
                  "The coarse instances to start from (labels of instascene decompose's output); "
                  "default: the labels of --features");
  seg->add_option("--out", segment->out, "Result directory")->required();
  segment->flags.Add(seg, training::SegmentSpec());
  seg->callback([segment, action] {
    *action = [segment]() -> absl::Status {
      ASSIGN_OR_RETURN(nlohmann::json parameters, segment->flags.Parameters());
      ASSIGN_OR_RETURN(
          training::SegmentStageOptions options,
          training::SegmentCodec().Decode(parameters.value("segment", nlohmann::json::object())));
      ASSIGN_OR_RETURN(Scene scene, ReadScene(segment->scene));
      ASSIGN_OR_RETURN(GaussianCloud cloud, ReadSceneGaussians(scene));
      ASSIGN_OR_RETURN(SegmentationResult in, ReadResult(segment->features, cloud.size()));
      if (in.feature_dim == 0)
        return absl::InvalidArgumentError(
            absl::StrCat(segment->features, ": result has no features"));
      if (!segment->decomposition.empty()) {
        ASSIGN_OR_RETURN(SegmentationResult coarse,
                         ReadResult(segment->decomposition, cloud.size()));
        in.labels = std::move(coarse.labels);
      }
      SegmentationResult out = in;
      out.stage = "segment";
      ASSIGN_OR_RETURN(out.labels, training::FinalLabels(in, cloud, options, 0, &out.metadata));
      RETURN_IF_ERROR(WriteResult(segment->out, out, cloud));
      RETURN_IF_ERROR(training::ExportInstances(segment->out, cloud, out.labels));
      std::fprintf(stderr, "segment: wrote %s\n", segment->out.c_str());
      return absl::OkStatus();
    };
  });
}

// The run's instance counts, coarse and final, from the stored results.
absl::Status CountInstances(const std::string& scene_dir, const std::filesystem::path& out,
                            size_t* coarse, size_t* final) {
  ASSIGN_OR_RETURN(Scene scene, ReadScene(scene_dir));
  ASSIGN_OR_RETURN(GaussianCloud cloud, ReadSceneGaussians(scene));
  auto count = [&](const char* stage) -> absl::StatusOr<size_t> {
    ASSIGN_OR_RETURN(SegmentationResult r, ReadResult((out / stage).string(), cloud.size()));
    std::set<uint32_t> ids(r.labels.begin(), r.labels.end());
    ids.erase(0);
    return ids.size();
  };
  ASSIGN_OR_RETURN(*coarse, count("decomposition"));
  ASSIGN_OR_RETURN(*final, count("segmentation"));
  return absl::OkStatus();
}

// The same stages and DAG the service workers run (services/pipeline), in this process.
absl::Status RunAllStages(const TrainArgs& run, const pipeline::StageRegistry& registry) {
  Stopwatch watch;
  const std::filesystem::path out(run.out);
  ASSIGN_OR_RETURN(nlohmann::json parameters, run.flags.Parameters());
  ASSIGN_OR_RETURN(std::vector<pipeline::PlannedStage> plan, registry.Plan(run.stages, parameters));
  pipeline::LocalRunOptions options;
  options.scene_dir = run.scene;
  options.out_dir = run.out;
  options.num_threads = run.threads;
  std::unique_ptr<ProgressBar> bar;
  std::string phase;
  options.progress = [&](const std::string& kind, int64_t item, const pipeline::StageProgress& p) {
    const std::string label = item < 0 ? absl::StrCat(kind, ": ", p.phase)
                                       : absl::StrCat(kind, "[", item, "]: ", p.phase);
    if (label != phase) {
      phase = label;
      bar = p.total > 1 ? std::make_unique<ProgressBar>(label) : nullptr;
    }
    if (bar) bar->Update(static_cast<int>(p.step), static_cast<int>(p.total));
  };
  ASSIGN_OR_RETURN(pipeline::LocalRunResult ran,
                   pipeline::RunPipelineLocally(registry, plan, options));
  nlohmann::json failed = nlohmann::json::object();
  for (const auto& [job, status] : ran.failures) {
    std::fprintf(stderr, "run: %s failed (the other items ran): %s\n", job.c_str(),
                 status.ToString().c_str());
    failed[job] = status.ToString();
  }
  const std::string result = (out / "segmentation").string();
  size_t coarse = 0, final = 0;
  RETURN_IF_ERROR(CountInstances(run.scene, out, &coarse, &final));
  const nlohmann::json summary = {{"instances", final},
                                  {"coarse_instances", coarse},
                                  {"decomposition", (out / "decomposition").string()},
                                  {"out", result},
                                  {"objects", (out / "objects").string()},
                                  {"failed", failed},
                                  {"seconds", watch.ElapsedSeconds()}};
  std::fprintf(stderr,
               "run: %zu instances (%zu coarse) in %.1f s; results in %s (evaluate with "
               "instascene eval --result %s)\n",
               final, coarse, watch.ElapsedSeconds(), run.out.c_str(), result.c_str());
  if (run.json) PrintJsonLine(summary.dump());
  return absl::OkStatus();
}

// `run`: every stage offline, the stage code the services run.
void AddRunCommand(CLI::App& app, Action* action) {
  auto run = std::make_shared<TrainArgs>();
  CLI::App* r = app.add_subcommand(
      "run",
      "All stages offline, the same stage code the services run: decompose, train, segment, "
      "complete, export (results under --out: decomposition/, training/, segmentation/, "
      "objects/<item>/, export/)");
  r->add_option("--scene", run->scene, "Scene directory (images, masks, gaussians.ply)")
      ->required();
  r->add_option("--out", run->out,
                "Output directory: one folder per stage (decomposition/, training/, "
                "segmentation/, objects/, export/)")
      ->required();
  r->add_option("--stages", run->stages,
                "Run only these stages (comma-separated, each with its inputs: e.g. "
                "decompose,train,segment skips completion and export); default: every stage")
      ->delimiter(',');
  auto registry = std::make_shared<pipeline::StageRegistry>();
  if (absl::Status s = stages::RegisterStages(registry.get()); !s.ok())
    throw std::logic_error(s.ToString());
  for (const std::string& kind : registry->Kinds()) run->flags.Add(r, registry->Find(kind)->spec);
  AddCommonOptions(r, run.get());
  r->callback([run, registry, action] {
    *action = [run, registry] { return RunAllStages(*run, *registry); };
  });
}

}  // namespace

void AddTrainCommands(CLI::App& app, Action* action) {
  AddTrainCommand(app, action);
  AddSegmentCommand(app, action);
  AddRunCommand(app, action);
}

}  // namespace instascene::cli
