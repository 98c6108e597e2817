// `instascene synth`: generate a synthetic cluttered scene with ground truth.
#include <cstdio>

#include <nlohmann/json.hpp>

#include "absl/strings/str_cat.h"
#include "clients/cli/cli.h"
#include "clients/cli/progress.h"
#include "common/core/status.h"
#include "common/core/timer.h"
#include "common/scene/image_io.h"
#include "common/splat/gaussian_ply.h"
#include "common/splat/splat_formats.h"
#include "common/synth/cluttered_scene.h"
#include "common/synth/observed_surfels.h"
#include "common/synth/scene_writer.h"
#include "common/synth/splat_composite.h"

#include <filesystem>

namespace instascene::cli {

void AddSynthCommand(CLI::App& app, Action* action) {
  struct Args {
    std::string out, preset = "small", mask_noise = "medium", unseen = "keep";
    std::vector<std::string> from_splats;
    double object_height = 0.5, asymmetric = 0.0, gap = 0.03;
    int64_t seed = -1, objects = -1, views = -1, width = -1, height = -1, gaussians = -1;
    int threads = 0, table_detail = 3;
    bool json = false;
  };
  auto args = std::make_shared<Args>();
  CLI::App* cmd =
      app.add_subcommand("synth", "Generate a synthetic cluttered scene with exact ground truth");
  cmd->add_option("--out", args->out, "Output scene directory")->required();
  cmd->add_option("--preset", args->preset, "Size preset: tiny, small (default), medium, large");
  cmd->add_option("--seed", args->seed, "Random seed (default 1)");
  cmd->add_option("--objects", args->objects, "Number of objects (overrides the preset)");
  cmd->add_option("--views", args->views, "Number of camera views");
  cmd->add_option("--width", args->width, "Image width, px");
  cmd->add_option("--height", args->height, "Image height, px");
  cmd->add_option("--gaussians", args->gaussians,
                  "Surfels sampled on the objects and the room (the table's refinement near "
                  "objects and one surfel per cone apex come on top)");
  cmd->add_option("--mask-noise", args->mask_noise,
                  "Simulated 2D segmenter noise: none, low, medium (default), high; the "
                  "independent part-aware family: sam-low, sam-medium, sam-high")
      ->check(
          CLI::IsMember({"none", "low", "medium", "high", "sam-low", "sam-medium", "sam-high"}));
  cmd->add_option(
         "--from-splats", args->from_splats,
         "Compose real captures (comma-separated .ply files) instead of procedural objects")
      ->delimiter(',');
  cmd->add_option("--object-height", args->object_height,
                  "With --from-splats: height each capture is scaled to");
  cmd->add_option("--gap", args->gap,
                  "With --from-splats: gap between neighbouring footprint circles, in object "
                  "heights (default 0.03; negative values push the captures into each other "
                  "until they touch)")
      ->check(CLI::Range(-1.0, 1.0));
  cmd->add_option("--asymmetric", args->asymmetric,
                  "Share of objects drawn from shapes without symmetry (mug with a handle, "
                  "L-block, irregular block); default 0");
  cmd->add_option("--table-detail", args->table_detail,
                  "Split table-top surfels whose disc reaches an object into N x N smaller ones "
                  "(default 3), as a model trained on photographs would; 1 = the coarse table of "
                  "scenes generated before 2026-12-03, whose discs painted over low objects")
      ->check(CLI::Range(1, 8));
  cmd->add_option("--unseen", args->unseen,
                  "Surfels no view sees: keep (default: every surface is covered) or drop (what "
                  "a model trained on the images would hold; for completion experiments)")
      ->check(CLI::IsMember({"keep", "drop"}));
  cmd->add_option("--threads", args->threads, "Rendering threads (0 = all cores)");
  cmd->add_flag("--json", args->json, "Print a JSON summary as the last stdout line");
  cmd->callback([args, action] {
    *action = [args]() -> absl::Status {
      ASSIGN_OR_RETURN(ClutterOptions options, ClutterPreset(args->preset));
      if (args->seed >= 0) options.seed = static_cast<uint64_t>(args->seed);
      if (args->objects >= 0) options.objects = static_cast<int>(args->objects);
      if (args->views >= 0) options.views = static_cast<int>(args->views);
      if (args->width >= 0) options.width = static_cast<int>(args->width);
      if (args->height >= 0) options.height = static_cast<int>(args->height);
      if (args->gaussians >= 0) options.gaussians = static_cast<size_t>(args->gaussians);
      options.asymmetric_share = static_cast<float>(args->asymmetric);
      options.table_detail = args->table_detail;
      Stopwatch watch;
      ClutterScene scene;
      if (args->from_splats.empty()) {
        ASSIGN_OR_RETURN(scene, GenerateClutterScene(options));
      } else {
        std::vector<GaussianCloud> clouds;
        std::vector<std::string> names;
        for (const std::string& path : args->from_splats) {
          ASSIGN_OR_RETURN(GaussianCloud cloud, ReadSplatFile(path));
          clouds.push_back(std::move(cloud));
          names.push_back(std::filesystem::path(path).stem().string());
        }
        CompositeOptions composite;
        composite.seed = options.seed;
        composite.views = options.views;
        composite.width = options.width;
        composite.height = options.height;
        composite.object_height = static_cast<float>(args->object_height);
        composite.gap = static_cast<float>(args->gap);
        ASSIGN_OR_RETURN(scene, ComposeSplats(clouds, names, composite));
        options.objects = static_cast<int>(clouds.size());
      }
      if (args->unseen == "drop") RETURN_IF_ERROR(DropUnseenSurfels(&scene, 0.01f, args->threads));
      ProgressBar bar("synth: rendering views");
      SceneWriteOptions write;
      write.num_threads = args->threads;
      write.mask_noise = args->mask_noise;
      write.seed = options.seed;
      write.progress = [&bar](int done, int total) { bar.Update(done, total); };
      RETURN_IF_ERROR(WriteClutterScene(scene, args->out, write));
      std::fprintf(stderr,
                   "synth: wrote %s: %zu Gaussians, %d objects, %zu views of %dx%d in %.1f s\n",
                   args->out.c_str(), scene.cloud.size(), options.objects, scene.cameras.size(),
                   options.width, options.height, watch.ElapsedSeconds());
      if (args->json) {
        nlohmann::json j = {{"scene", args->out},
                            {"gaussians", scene.cloud.size()},
                            {"objects", options.objects},
                            {"views", scene.cameras.size()},
                            {"seconds", watch.ElapsedSeconds()}};
        PrintJsonLine(j.dump());
      }
      return absl::OkStatus();
    };
  });
}

}  // namespace instascene::cli
