// `instascene eval`: score a result directory against a synthetic scene's ground truth.
#include <cstdio>

#include <nlohmann/json.hpp>

#include "clients/cli/cli.h"
#include "common/core/status.h"
#include "common/core/timer.h"
#include "common/eval/click_eval.h"
#include "common/scene/image_io.h"

namespace instascene::cli {

void AddEvalCommand(CLI::App& app, Action* action) {
  struct Args {
    std::string scene, result;
    ClickEvalOptions options;
    bool labels_only = false, json = false;
  };
  auto args = std::make_shared<Args>();
  CLI::App* cmd = app.add_subcommand("eval",
                                     "Click-protocol mIoU and 3D instance metrics of a result "
                                     "against the scene's ground truth (needs gt/)");
  cmd->add_option("--scene", args->scene, "Scene directory with ground truth")->required();
  cmd->add_option("--result", args->result,
                  "Result directory (result.json + labels.ply [+ features.ply]); <scene>/gt scores "
                  "the ground truth")
      ->required();
  cmd->add_option("--threshold", args->options.feature_threshold,
                  "Cosine threshold of feature masks (default 0.9)");
  cmd->add_option("--min-visible", args->options.min_visible_pixels,
                  "GT pixels for an object to count as visible in a view (default 20)");
  cmd->add_flag("--labels-only", args->labels_only, "Ignore the result's features; use its labels");
  cmd->add_option("--threads", args->options.num_threads, "Threads (0 = all cores)");
  cmd->add_flag("--json", args->json, "Print the scores as one JSON line (last stdout line)");
  cmd->callback([args, action] {
    *action = [args]() -> absl::Status {
      Stopwatch watch;
      ClickEvalOptions options = args->options;
      options.use_features = !args->labels_only;
      ASSIGN_OR_RETURN(ClickEvaluation eval,
                       EvaluateResultDirectory(args->scene, args->result, options));
      std::printf("%-20s %6s %5s %8s\n", "object", "ref", "views", "IoU");
      nlohmann::json objects = nlohmann::json::array();
      for (const ObjectClickScore& o : eval.objects) {
        std::printf("%-20s %6d %5d %8.4f\n", o.name.c_str(), o.reference_view, o.views, o.miou);
        objects.push_back({{"id", o.id},
                           {"name", o.name},
                           {"reference_view", o.reference_view},
                           {"views", o.views},
                           {"miou", o.miou}});
      }
      std::printf(
          "mIoU %.4f (%s, %zu objects); 3D: precision %.3f recall %.3f mean best IoU %.3f ARI %.3f "
          "(%.1f s)\n",
          eval.miou, eval.used_features ? "features" : "labels", eval.objects.size(),
          eval.instances.precision, eval.instances.recall, eval.instances.mean_best_iou,
          eval.adjusted_rand_index, watch.ElapsedSeconds());
      if (args->json) {
        PrintJsonLine(nlohmann::json({{"miou", eval.miou},
                                      {"objects", objects},
                                      {"mode", eval.used_features ? "features" : "labels"},
                                      {"precision_3d", eval.instances.precision},
                                      {"recall_3d", eval.instances.recall},
                                      {"mean_best_iou_3d", eval.instances.mean_best_iou},
                                      {"predicted_instances", eval.instances.predicted},
                                      {"ari", eval.adjusted_rand_index},
                                      {"observed_gaussians", eval.observed_gaussians}})
                          .dump());
      }
      return absl::OkStatus();
    };
  });
}

}  // namespace instascene::cli
