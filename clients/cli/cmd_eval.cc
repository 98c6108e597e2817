// `instascene eval`: score a result directory against a synthetic scene's ground truth.
#include <cstdio>

#include <nlohmann/json.hpp>

#include "absl/strings/str_format.h"
#include "clients/cli/cli.h"
#include "common/core/status.h"
#include "common/core/timer.h"
#include "common/eval/click_eval.h"
#include "common/scene/image_io.h"
#include "services/generation/completion_eval.h"
#include "services/objects/export_eval.h"

namespace instascene::cli {
namespace {

absl::Status EvaluateCompletionCommand(const std::string& scene, const std::string& objects,
                                       int threads, bool json) {
  Stopwatch watch;
  generation::CompletionEvalOptions options;
  options.num_threads = threads;
  ASSIGN_OR_RETURN(std::vector<generation::ObjectCompletionEval> evals,
                   generation::EvaluateCompletion(scene, objects, options));
  for (const generation::ObjectCompletionEval& e : evals) {
    std::printf(
        "%-14s %-8s chamfer%% raw %.2f closed %.2f completed %.2f | F1@2%% %.3f %.3f "
        "%.3f | vIoU %.3f %.3f %.3f | hidden recall %.3f %.3f %.3f | PSNR unknown "
        "%s | violations %d%s\n",
        e.gt_name.c_str(), e.shape.c_str(), 100 * e.raw.chamfer, 100 * e.closed.chamfer,
        100 * e.completed.chamfer, e.raw.f1.size() > 1 ? e.raw.f1[1] : 0,
        e.closed.f1.size() > 1 ? e.closed.f1[1] : 0,
        e.completed.f1.size() > 1 ? e.completed.f1[1] : 0, e.raw.volume_iou, e.closed.volume_iou,
        e.completed.volume_iou, e.raw.hidden_recall, e.closed.hidden_recall,
        e.completed.hidden_recall,
        e.unknown_views == 0
            ? "n/a (no unknown view)"
            : absl::StrFormat("%.2f -> %.2f", e.raw.psnr_unknown, e.completed.psnr_unknown).c_str(),
        e.completed.free_space_violations, e.abstained ? " (abstained)" : "");
  }
  const nlohmann::json j = generation::CompletionEvalJson(evals, options);
  for (const char* v : {"raw", "closed", "completed"}) {
    if (!j["mean"].contains(v)) continue;
    const nlohmann::json& m = j["mean"][v];
    std::printf(
        "mean %-9s chamfer %.4f  vIoU %.3f  hidden recall %.3f  PSNR known %.2f unknown "
        "%.2f  violations %d\n",
        v, m["chamfer"].get<double>(), m["volume_iou"].get<double>(),
        m["hidden_recall"].get<double>(), m["psnr_known"].get<double>(),
        m["psnr_unknown"].get<double>(), static_cast<int>(m["free_space_violations"]));
  }
  std::printf("(%d objects matched, %.1f s)\n", j["matched"].get<int>(), watch.ElapsedSeconds());
  if (json) PrintJsonLine(j.dump());
  return absl::OkStatus();
}

absl::Status EvaluateExportCommand(const std::string& scene, const std::string& export_dir,
                                   bool json) {
  ASSIGN_OR_RETURN(std::vector<objects::ExportObjectEval> evals,
                   objects::EvaluateExport(scene, export_dir));
  std::printf("%-6s %-16s %-26s %-26s %8s %10s\n", "object", "ground truth", "extent (m)",
              "gt extent (m)", "error", "chamfer m");
  for (const objects::ExportObjectEval& e : evals)
    std::printf("%-6u %-16s %7.3f %7.3f %7.3f    %7.3f %7.3f %7.3f    %7.1f%% %10.4f\n", e.id,
                e.gt_name.c_str(), e.extent.x(), e.extent.y(), e.extent.z(), e.gt_extent.x(),
                e.gt_extent.y(), e.gt_extent.z(), 100 * e.extent_error, e.chamfer);
  if (json) std::printf("%s\n", objects::ExportEvalJson(evals).dump().c_str());
  return absl::OkStatus();
}

struct EvalArgs {
  std::string scene, result, completion, export_dir;
  ClickEvalOptions options;
  bool labels_only = false, json = false;
};

absl::Status EvaluateClicksCommand(const EvalArgs& a) {
  Stopwatch watch;
  ClickEvalOptions options = a.options;
  options.use_features = !a.labels_only;
  ASSIGN_OR_RETURN(ClickEvaluation eval, EvaluateResultDirectory(a.scene, a.result, options));
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
  if (a.json) {
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
}

absl::Status RunEval(const EvalArgs& a) {
  if ((!a.result.empty()) + (!a.completion.empty()) + (!a.export_dir.empty()) != 1)
    return absl::InvalidArgumentError("give exactly one of --result, --completion and --export");
  if (!a.export_dir.empty()) return EvaluateExportCommand(a.scene, a.export_dir, a.json);
  if (!a.completion.empty()) {
    return EvaluateCompletionCommand(a.scene, a.completion, a.options.num_threads, a.json);
  }
  return EvaluateClicksCommand(a);
}

}  // namespace

void AddEvalCommand(CLI::App& app, Action* action) {
  auto args = std::make_shared<EvalArgs>();
  CLI::App* cmd = app.add_subcommand("eval",
                                     "Click-protocol mIoU and 3D instance metrics of a result "
                                     "against the scene's ground truth (needs gt/)");
  cmd->add_option("--scene", args->scene, "Scene directory with ground truth")->required();
  cmd->add_option("--result", args->result,
                  "Result directory (result.json + labels.ply [+ features.ply]); <scene>/gt scores "
                  "the ground truth");
  cmd->add_option("--completion", args->completion,
                  "Instead: score completed objects (a folder of per-object folders, e.g. "
                  "<run>/objects) for the raw crop, the closed crop and the completed object");
  cmd->add_option("--export", args->export_dir,
                  "Instead: score exported objects (the export stage's folder) in metres: extents "
                  "against the ground-truth object's, and the placed mesh's Chamfer distance");
  cmd->add_option("--threshold", args->options.feature_threshold,
                  "Cosine threshold of feature masks (default 0.9)");
  cmd->add_option("--min-visible", args->options.min_visible_pixels,
                  "GT pixels for an object to count as visible in a view (default 20)");
  cmd->add_flag("--labels-only", args->labels_only, "Ignore the result's features; use its labels");
  cmd->add_option("--threads", args->options.num_threads, "Threads (0 = all cores)");
  cmd->add_flag("--json", args->json, "Print the scores as one JSON line (last stdout line)");
  cmd->callback([args, action] { *action = [args] { return RunEval(*args); }; });
}

}  // namespace instascene::cli
