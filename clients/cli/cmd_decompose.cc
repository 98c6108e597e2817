// `instascene decompose`: spatial Gaussian trackers + view-consensus mask clustering.
#include <cstdio>

#include <nlohmann/json.hpp>

#include "clients/cli/cli.h"
#include "clients/cli/progress.h"
#include "clients/cli/stage_flags.h"
#include "common/core/status.h"
#include "common/core/timer.h"
#include "services/decomposition/decompose.h"
#include "services/decomposition/stage_params.h"

namespace instascene::cli {

namespace {

struct DecomposeArgs {
  std::string scene, out;
  StageFlags flags;
  int threads = 0;
  bool json = false;
};

void PrintDecomposition(const DecomposeArgs& a, const decomposition::DecompositionResult& result,
                        size_t gaussians, double seconds) {
  size_t assigned = 0;
  for (uint32_t l : result.Labels()) assigned += l != 0;
  std::fprintf(stderr,
               "decompose: %zu trackers, %zu instances, %zu under-segmented masks left; %zu of %zu "
               "Gaussians "
               "labelled; tracking %.1f s, clustering %.1f s, post-processing %.1f s; wrote %s\n",
               result.trackers.trackers.size(), result.instances.size(),
               result.undersegmented.size(), assigned, gaussians, result.tracking_seconds,
               result.clustering_seconds, result.post_seconds, a.out.c_str());
  if (a.json) {
    PrintJsonLine(nlohmann::json({{"out", a.out},
                                  {"instances", result.instances.size()},
                                  {"trackers", result.trackers.trackers.size()},
                                  {"undersegmented", result.undersegmented.size()},
                                  {"tracking_s", result.tracking_seconds},
                                  {"clustering_s", result.clustering_seconds},
                                  {"post_s", result.post_seconds},
                                  {"seconds", seconds}})
                      .dump());
  }
}

absl::Status RunDecompose(const DecomposeArgs& a) {
  Stopwatch watch;
  ASSIGN_OR_RETURN(nlohmann::json parameters, a.flags.Parameters());
  ASSIGN_OR_RETURN(decomposition::DecompositionOptions options,
                   decomposition::DecomposeCodec().Decode(
                       parameters.value("decompose", nlohmann::json::object())));
  options.num_threads = a.threads;
  ASSIGN_OR_RETURN(Scene scene, ReadScene(a.scene));
  ASSIGN_OR_RETURN(GaussianCloud cloud, ReadSceneGaussians(scene));
  ProgressBar bar("decompose: tracking");
  auto progress = [&bar](const std::string& stage, int done, int total) {
    if (stage == "tracking")
      bar.Update(done, total);
    else if (done == total)
      std::fprintf(stderr, "decompose: %s done\n", stage.c_str());
  };
  ASSIGN_OR_RETURN(decomposition::DecompositionResult result,
                   decomposition::Decompose(scene, cloud, options, progress));
  RETURN_IF_ERROR(decomposition::WriteDecomposition(a.out, scene, cloud, result));
  PrintDecomposition(a, result, cloud.size(), watch.ElapsedSeconds());
  return absl::OkStatus();
}

}  // namespace

void AddDecomposeCommand(CLI::App& app, Action* action) {
  auto args = std::make_shared<DecomposeArgs>();
  CLI::App* cmd = app.add_subcommand(
      "decompose", "Cluster per-view 2D masks into 3D instances (spatial Gaussian trackers)");
  cmd->add_option("--scene", args->scene, "Scene directory (needs masks/)")->required();
  cmd->add_option("--out", args->out,
                  "Output directory (result format + decomposition.json + per-view maps)")
      ->required();
  args->flags.Add(cmd, decomposition::DecomposeSpec());  // the decompose job's parameters
  cmd->add_option("--threads", args->threads, "Threads (0 = all cores)");
  cmd->add_flag("--json", args->json, "Print a JSON summary as the last stdout line");
  cmd->callback([args, action] { *action = [args] { return RunDecompose(*args); }; });
}

}  // namespace instascene::cli
