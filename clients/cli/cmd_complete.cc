// `instascene complete`: in-situ completion of segmented objects, offline (the `complete` stage's
// code, one object after the other).
#include <cstdio>
#include <filesystem>
#include <set>

#include <nlohmann/json.hpp>

#include "absl/strings/str_cat.h"
#include "clients/cli/cli.h"
#include "clients/cli/progress.h"
#include "clients/cli/stage_flags.h"
#include "common/core/status.h"
#include "common/core/timer.h"
#include "common/eval/result.h"
#include "common/scene/image_io.h"
#include "common/scene/scene.h"
#include "services/generation/completion.h"
#include "services/generation/stage.h"
#include "services/generation/stage_params.h"

namespace instascene::cli {

namespace {

struct CompleteArgs {
  std::string scene, result, out;
  std::vector<uint32_t> objects;
  std::string denoiser;
  StageFlags flags;
  int threads = 0;
  bool json = false;
};

absl::StatusOr<generation::CompletionOptions> CompletionOptionsOf(const CompleteArgs& a) {
  ASSIGN_OR_RETURN(nlohmann::json parameters, a.flags.Parameters());
  ASSIGN_OR_RETURN(
      generation::CompleteStageOptions stage_options,
      generation::CompleteCodec().Decode(parameters.value("complete", nlohmann::json::object())));
  generation::CompletionOptions options = generation::ToCompletionOptions(stage_options);
  options.num_threads = a.threads;
  options.denoiser = a.denoiser;
  return options;
}

// Completes and writes one object; its entry for the summary, or the failure.
absl::StatusOr<nlohmann::json> CompleteOne(const CompleteArgs& a,
                                           const std::vector<PinholeCamera>& cameras,
                                           const GaussianCloud& cloud,
                                           const SegmentationResult& result, uint32_t id,
                                           const generation::CompletionOptions& options) {
  ProgressBar bar(absl::StrCat("complete ", id));
  ASSIGN_OR_RETURN(const generation::CompletedObject object,
                   generation::CompleteObject(
                       cameras, cloud, result.labels, id, options,
                       [&](const std::string&, int step, int total) { bar.Update(step, total); }));
  const std::string dir = (std::filesystem::path(a.out) / std::to_string(id)).string();
  RETURN_IF_ERROR(generation::WriteCompletedObject(dir, object, a.threads));
  const nlohmann::json& m = object.manifest;
  std::fprintf(stderr,
               "complete: object %u: %zu observed + %zu completed Gaussians (%s), %d known "
               "/ %d unknown ring views, mesh %zu triangles%s -> %s\n",
               id, object.raw.size(), object.object.size() - object.raw.size(),
               object.prior.reason.c_str(), m["known_views"].get<int>(),
               m["unknown_views"].get<int>(), object.mesh.triangles.size(),
               m["mesh"]["closed"].get<bool>() ? " (closed)" : "", dir.c_str());
  return nlohmann::json{{"id", id}, {"dir", dir}, {"abstained", object.prior.abstained}};
}

absl::Status RunComplete(const CompleteArgs& a) {
  Stopwatch watch;
  ASSIGN_OR_RETURN(generation::CompletionOptions options, CompletionOptionsOf(a));
  ASSIGN_OR_RETURN(Scene scene, ReadScene(a.scene));
  ASSIGN_OR_RETURN(GaussianCloud cloud, ReadSceneGaussians(scene));
  cloud = ToSurfels(cloud);
  ASSIGN_OR_RETURN(SegmentationResult result, ReadResult(a.result, cloud.size()));
  std::vector<PinholeCamera> cameras;
  for (const SceneView& view : scene.views) cameras.push_back(view.camera);
  options.load_view = [&scene](int view) { return ReadViewImage(scene, view); };
  std::set<uint32_t> ids(a.objects.begin(), a.objects.end());
  if (ids.empty()) {
    ids.insert(result.labels.begin(), result.labels.end());
    ids.erase(0);
  }
  nlohmann::json done = nlohmann::json::array(), failed = nlohmann::json::object();
  for (uint32_t id : ids) {
    absl::StatusOr<nlohmann::json> entry = CompleteOne(a, cameras, cloud, result, id, options);
    if (!entry.ok()) {
      std::fprintf(stderr, "complete: object %u failed: %s\n", id,
                   entry.status().ToString().c_str());
      failed[std::to_string(id)] = entry.status().ToString();
      continue;
    }
    done.push_back(*std::move(entry));
  }
  std::fprintf(stderr, "complete: %zu of %zu objects in %.1f s\n", done.size(), ids.size(),
               watch.ElapsedSeconds());
  if (a.json) {
    PrintJsonLine(
        nlohmann::json({{"objects", done}, {"failed", failed}, {"seconds", watch.ElapsedSeconds()}})
            .dump());
  }
  if (done.empty() && !ids.empty()) {
    return absl::FailedPreconditionError("no object could be completed");
  }
  return absl::OkStatus();
}

}  // namespace

void AddCompleteCommand(CLI::App& app, Action* action) {
  auto args = std::make_shared<CompleteArgs>();
  CLI::App* cmd = app.add_subcommand(
      "complete",
      "Complete segmented objects in situ (viewpoint ring, free space, completion prior, mesh); "
      "one folder per object under --out");
  cmd->add_option("--scene", args->scene, "Scene directory")->required();
  cmd->add_option("--result", args->result,
                  "Segmentation result (labels.ply; e.g. <run>/segmentation)")
      ->required();
  cmd->add_option("--out", args->out, "Output directory (one <id>/ folder per object)")->required();
  cmd->add_option("--object", args->objects, "Instance ids to complete (default: all)");
  args->flags.Add(cmd, generation::CompleteSpec());
  cmd->add_option("--denoiser", args->denoiser,
                  "--prior diffusion: the Denoiser service, grpc://HOST:PORT, or an ONNX model, "
                  "onnx:FILE.json (no model weights ship with InstaScene; docs/GENERATION.md)");
  cmd->add_option("--threads", args->threads, "Threads (0 = all cores)");
  cmd->add_flag("--json", args->json, "Print a JSON summary as the last stdout line");
  cmd->callback([args, action] { *action = [args] { return RunComplete(*args); }; });
}

}  // namespace instascene::cli
