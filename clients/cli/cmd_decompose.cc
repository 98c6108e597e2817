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

void AddDecomposeCommand(CLI::App& app, Action* action) {
  struct Args {
    std::string scene, out;
    StageFlags flags;
    int threads = 0;
    bool json = false;
  };
  auto args = std::make_shared<Args>();
  CLI::App* cmd = app.add_subcommand(
      "decompose", "Cluster per-view 2D masks into 3D instances (spatial Gaussian trackers)");
  cmd->add_option("--scene", args->scene, "Scene directory (needs masks/)")->required();
  cmd->add_option("--out", args->out,
                  "Output directory (result format + decomposition.json + per-view maps)")
      ->required();
  args->flags.Add(cmd, decomposition::DecomposeSpec());  // the decompose job's parameters
  cmd->add_option("--threads", args->threads, "Threads (0 = all cores)");
  cmd->add_flag("--json", args->json, "Print a JSON summary as the last stdout line");
  cmd->callback([args, action] {
    *action = [args]() -> absl::Status {
      Stopwatch watch;
      ASSIGN_OR_RETURN(nlohmann::json parameters, args->flags.Parameters());
      ASSIGN_OR_RETURN(decomposition::DecompositionOptions options,
                       decomposition::DecomposeCodec().Decode(
                           parameters.value("decompose", nlohmann::json::object())));
      options.num_threads = args->threads;
      ASSIGN_OR_RETURN(Scene scene, ReadScene(args->scene));
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
      RETURN_IF_ERROR(decomposition::WriteDecomposition(args->out, scene, cloud, result));
      size_t assigned = 0;
      for (uint32_t l : result.Labels()) assigned += l != 0;
      std::fprintf(
          stderr,
          "decompose: %zu trackers, %zu instances, %zu under-segmented masks left; %zu of %zu "
          "Gaussians "
          "labelled; tracking %.1f s, clustering %.1f s, post-processing %.1f s; wrote %s\n",
          result.trackers.trackers.size(), result.instances.size(), result.undersegmented.size(),
          assigned, cloud.size(), result.tracking_seconds, result.clustering_seconds,
          result.post_seconds, args->out.c_str());
      if (args->json) {
        PrintJsonLine(nlohmann::json({{"out", args->out},
                                      {"instances", result.instances.size()},
                                      {"trackers", result.trackers.trackers.size()},
                                      {"undersegmented", result.undersegmented.size()},
                                      {"tracking_s", result.tracking_seconds},
                                      {"clustering_s", result.clustering_seconds},
                                      {"post_s", result.post_seconds},
                                      {"seconds", watch.ElapsedSeconds()}})
                          .dump());
      }
      return absl::OkStatus();
    };
  });
}

}  // namespace instascene::cli
