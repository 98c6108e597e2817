// `instascene decompose`: spatial Gaussian trackers + view-consensus mask clustering.
#include <cstdio>

#include <nlohmann/json.hpp>

#include "clients/cli/cli.h"
#include "clients/cli/progress.h"
#include "common/core/status.h"
#include "common/core/timer.h"
#include "services/decomposition/decompose.h"

namespace instascene::cli {

void AddDecomposeCommand(CLI::App& app, Action* action) {
  struct Args {
    std::string scene, out, rule = "weight";
    decomposition::DecompositionOptions options;
    bool json = false;
  };
  auto args = std::make_shared<Args>();
  CLI::App* cmd = app.add_subcommand(
      "decompose", "Cluster per-view 2D masks into 3D instances (spatial Gaussian trackers)");
  cmd->add_option("--scene", args->scene, "Scene directory (needs masks/)")->required();
  cmd->add_option("--out", args->out,
                  "Output directory (result format + decomposition.json + per-view maps)")
      ->required();
  cmd->add_option("--tracker-rule", args->rule,
                  "weight (w > 0.1, release) or median (T crosses 0.5, paper)")
      ->check(CLI::IsMember({"weight", "median"}));
  cmd->add_option("--min-tracker", args->options.min_tracker_gaussians,
                  "Minimum Gaussians per mask tracker (50)");
  cmd->add_option(
      "--dbscan-eps", args->options.dbscan_eps,
      "DBSCAN radius: scene units, or a fraction of the scene diagonal with --relative-eps (0.1)");
  cmd->add_flag("--relative-eps", args->options.dbscan_eps_relative,
                "Interpret --dbscan-eps relative to the robust scene diagonal");
  cmd->add_option("--threads", args->options.num_threads, "Threads (0 = all cores)");
  cmd->add_flag("--json", args->json, "Print a JSON summary as the last stdout line");
  cmd->callback([args, action] {
    *action = [args]() -> absl::Status {
      Stopwatch watch;
      decomposition::DecompositionOptions options = args->options;
      options.tracker_rule = args->rule == "median" ? decomposition::TrackerRule::kMedianCrossing
                                                    : decomposition::TrackerRule::kWeight;
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
