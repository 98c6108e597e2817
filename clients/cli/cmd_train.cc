// `instascene train`, `instascene segment` and `instascene run` (decompose + train + segment).
#include <cstdio>
#include <filesystem>

#include <nlohmann/json.hpp>

#include "clients/cli/cli.h"
#include "clients/cli/progress.h"
#include "common/core/status.h"
#include "common/core/timer.h"
#include "common/eval/result.h"
#include "services/decomposition/decompose.h"
#include "services/pipeline/stages.h"
#include "services/training/feature_field.h"
#include "services/training/segmentation.h"
#include "services/training/vote.h"

#include <map>
#include <set>

namespace instascene::cli {
namespace {

struct TrainArgs {
  std::string scene, decomposition, out, supervision = "full", method = "contrastive";
  training::TrainingOptions options;
  double threshold = 0.9;
  bool json = false;
};

void AddTrainingOptions(CLI::App* cmd, TrainArgs* args) {
  cmd->add_option("--iterations", args->options.iterations, "Optimisation steps (default 1500)");
  cmd->add_option("--samples", args->options.samples,
                  "Samples per loss term and step (default 4096)");
  cmd->add_option("--pixel-pool", args->options.pixel_pool,
                  "Traced pixels cached per view (default 8192)");
  cmd->add_option("--supervision", args->supervision,
                  "Loss terms: noisy2d, 3d, 3d+filtered2d, full (paper Table 2)")
      ->check(CLI::IsMember({"noisy2d", "3d", "3d+filtered2d", "full"}));
  cmd->add_option("--threshold", args->threshold, "Segmentation threshold tau (default 0.9)");
  cmd->add_option("--method", args->method,
                  "contrastive (the paper's feature field) or vote (training-free baseline)")
      ->check(CLI::IsMember({"contrastive", "vote"}));
  cmd->add_option("--seed", args->options.seed, "Random seed");
  cmd->add_option("--threads", args->options.num_threads, "Threads (0 = all cores)");
  cmd->add_flag("--json", args->json, "Print a JSON summary as the last stdout line");
}

// Trains on a decomposition and writes the segmented result (result format + instances).
absl::Status TrainAndSegment(const TrainArgs& args, const Scene& scene, const GaussianCloud& cloud,
                             const std::string& decomposition_dir, nlohmann::json* summary) {
  if (args.method == "vote") {
    Stopwatch watch;
    SegmentationResult result;
    result.stage = "vote";
    ASSIGN_OR_RETURN(result.labels, training::VoteLabels(scene, cloud, decomposition_dir,
                                                         args.options.num_threads));
    RETURN_IF_ERROR(WriteResult(args.out, result, cloud));
    RETURN_IF_ERROR(training::ExportInstances(args.out, cloud, result.labels));
    std::fprintf(stderr, "vote: labels by weighted 2D-mask voting in %.1f s; wrote %s\n",
                 watch.ElapsedSeconds(), args.out.c_str());
    (*summary)["out"] = args.out;
    return absl::OkStatus();
  }
  training::TrainingOptions options = args.options;
  ASSIGN_OR_RETURN(options.supervision, training::ParseSupervision(args.supervision));
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
  SegmentationResult result = training::TrainedResult(trained, data, options.feature_dim,
                                                      training::SegmentOptions{args.threshold});
  result.metadata["supervision"] = args.supervision;
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

}  // namespace

void AddTrainCommands(CLI::App& app, Action* action) {
  auto train = std::make_shared<TrainArgs>();
  CLI::App* cmd = app.add_subcommand(
      "train", "Train the spatial contrastive feature field on a decomposition, then segment");
  cmd->add_option("--scene", train->scene, "Scene directory")->required();
  cmd->add_option("--decomposition", train->decomposition, "Output of instascene decompose")
      ->required();
  cmd->add_option("--out", train->out, "Result directory (features, labels, instances/*.ply)")
      ->required();
  AddTrainingOptions(cmd, train.get());
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

  struct SegmentArgs {
    std::string scene, features, out;
    double threshold = 0.9;
  };
  auto segment = std::make_shared<SegmentArgs>();
  CLI::App* seg = app.add_subcommand(
      "segment", "Re-segment trained features (instances from their coarse labels, tau rule)");
  seg->add_option("--scene", segment->scene, "Scene directory")->required();
  seg->add_option("--features", segment->features,
                  "A result directory with features (instascene train)")
      ->required();
  seg->add_option("--out", segment->out, "Result directory")->required();
  seg->add_option("--threshold", segment->threshold, "Segmentation threshold tau (default 0.9)");
  seg->callback([segment, action] {
    *action = [segment]() -> absl::Status {
      ASSIGN_OR_RETURN(Scene scene, ReadScene(segment->scene));
      ASSIGN_OR_RETURN(GaussianCloud cloud, ReadSceneGaussians(scene));
      ASSIGN_OR_RETURN(SegmentationResult in, ReadResult(segment->features, cloud.size()));
      if (in.feature_dim == 0)
        return absl::InvalidArgumentError(
            absl::StrCat(segment->features, ": result has no features"));
      SegmentationResult out = in;
      out.stage = "segment";
      out.labels = training::SegmentByFeatures(in.features, in.feature_dim, in.labels,
                                               training::SegmentOptions{segment->threshold});
      RETURN_IF_ERROR(WriteResult(segment->out, out, cloud));
      RETURN_IF_ERROR(training::ExportInstances(segment->out, cloud, out.labels));
      std::fprintf(stderr, "segment: wrote %s\n", segment->out.c_str());
      return absl::OkStatus();
    };
  });

  auto run = std::make_shared<TrainArgs>();
  CLI::App* r = app.add_subcommand(
      "run",
      "All stages offline, the same stage code the services run: decompose, train, segment "
      "(results under --out: decomposition/, training/, segmentation/)");
  r->add_option("--scene", run->scene, "Scene directory (images, masks, gaussians.ply)")
      ->required();
  r->add_option("--out", run->out, "Output directory: decomposition/ and segmentation/")
      ->required();
  AddTrainingOptions(r, run.get());
  r->callback([run, action] {
    *action = [run]() -> absl::Status {
      // The same stage functions the service workers run (services/pipeline), in order.
      Stopwatch watch;
      const std::filesystem::path out(run->out);
      nlohmann::json train_parameters = {{"iterations", run->options.iterations},
                                         {"samples", run->options.samples},
                                         {"pixel_pool", run->options.pixel_pool},
                                         {"supervision", run->supervision},
                                         {"method", run->method},
                                         {"seed", run->options.seed}};
      const std::vector<std::pair<std::string, nlohmann::json>> stages = {
          {"decompose", nlohmann::json::object()},
          {"train", train_parameters},
          {"segment", {{"threshold", run->threshold}}}};
      const std::map<std::string, std::string> dirs = {
          {"decompose", "decomposition"}, {"train", "training"}, {"segment", "segmentation"}};
      std::string input;
      for (const auto& [kind, parameters] : stages) {
        pipeline::StageContext context;
        context.scene_dir = run->scene;
        context.input_dir = input;
        context.out_dir = (out / dirs.at(kind)).string();
        context.parameters = parameters;
        context.num_threads = run->options.num_threads;
        std::unique_ptr<ProgressBar> bar;
        std::string phase;
        context.progress = [&](const pipeline::StageProgress& p) {
          if (p.phase != phase) {
            phase = p.phase;
            bar = p.total > 1 ? std::make_unique<ProgressBar>(absl::StrCat(kind, ": ", p.phase))
                              : nullptr;
          }
          if (bar) bar->Update(static_cast<int>(p.step), static_cast<int>(p.total));
        };
        RETURN_IF_ERROR(pipeline::RunStage(kind, context));
        input = context.out_dir;
      }
      const std::string result = (out / "segmentation").string();
      ASSIGN_OR_RETURN(Scene scene, ReadScene(run->scene));
      ASSIGN_OR_RETURN(GaussianCloud cloud, ReadSceneGaussians(scene));
      ASSIGN_OR_RETURN(SegmentationResult coarse,
                       ReadResult((out / "decomposition").string(), cloud.size()));
      ASSIGN_OR_RETURN(SegmentationResult final_result, ReadResult(result, cloud.size()));
      std::set<uint32_t> coarse_ids(coarse.labels.begin(), coarse.labels.end());
      std::set<uint32_t> final_ids(final_result.labels.begin(), final_result.labels.end());
      coarse_ids.erase(0);
      final_ids.erase(0);
      const nlohmann::json summary = {{"instances", final_ids.size()},
                                      {"coarse_instances", coarse_ids.size()},
                                      {"decomposition", (out / "decomposition").string()},
                                      {"out", result},
                                      {"seconds", watch.ElapsedSeconds()}};
      std::fprintf(stderr,
                   "run: %zu instances (%zu coarse) in %.1f s; results in %s (evaluate with "
                   "instascene eval --result %s)\n",
                   final_ids.size(), coarse_ids.size(), watch.ElapsedSeconds(), run->out.c_str(),
                   result.c_str());
      if (run->json) PrintJsonLine(summary.dump());
      return absl::OkStatus();
    };
  });
}

}  // namespace instascene::cli
