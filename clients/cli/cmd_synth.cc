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

namespace {

struct SynthArgs {
  std::string out, preset = "small", mask_noise = "medium", unseen = "keep";
  std::vector<std::string> from_splats;
  double object_height = 0.5, asymmetric = 0.0, gap = 0.03;
  int64_t seed = -1, objects = -1, views = -1, width = -1, height = -1, gaussians = -1;
  int threads = 0, table_detail = 3;
  bool json = false;
};

// The preset with the flags that override it.
absl::StatusOr<ClutterOptions> SynthOptions(const SynthArgs& a) {
  ASSIGN_OR_RETURN(ClutterOptions options, ClutterPreset(a.preset));
  if (a.seed >= 0) options.seed = static_cast<uint64_t>(a.seed);
  if (a.objects >= 0) options.objects = static_cast<int>(a.objects);
  if (a.views >= 0) options.views = static_cast<int>(a.views);
  if (a.width >= 0) options.width = static_cast<int>(a.width);
  if (a.height >= 0) options.height = static_cast<int>(a.height);
  if (a.gaussians >= 0) options.gaussians = static_cast<size_t>(a.gaussians);
  options.asymmetric_share = static_cast<float>(a.asymmetric);
  options.table_detail = a.table_detail;
  return options;
}

// Real captures composed into one scene (--from-splats).
absl::StatusOr<ClutterScene> ComposeCaptures(const SynthArgs& a, const ClutterOptions& options) {
  std::vector<GaussianCloud> clouds;
  std::vector<std::string> names;
  for (const std::string& path : a.from_splats) {
    ASSIGN_OR_RETURN(GaussianCloud cloud, ReadSplatFile(path));
    clouds.push_back(std::move(cloud));
    names.push_back(std::filesystem::path(path).stem().string());
  }
  CompositeOptions composite;
  composite.seed = options.seed;
  composite.views = options.views;
  composite.width = options.width;
  composite.height = options.height;
  composite.object_height = static_cast<float>(a.object_height);
  composite.gap = static_cast<float>(a.gap);
  return ComposeSplats(clouds, names, composite);
}

absl::Status RunSynth(const SynthArgs& a) {
  ASSIGN_OR_RETURN(ClutterOptions options, SynthOptions(a));
  Stopwatch watch;
  ClutterScene scene;
  if (a.from_splats.empty()) {
    ASSIGN_OR_RETURN(scene, GenerateClutterScene(options));
  } else {
    ASSIGN_OR_RETURN(scene, ComposeCaptures(a, options));
    options.objects = static_cast<int>(a.from_splats.size());
  }
  if (a.unseen == "drop") RETURN_IF_ERROR(DropUnseenSurfels(&scene, 0.01f, a.threads));
  ProgressBar bar("synth: rendering views");
  SceneWriteOptions write;
  write.num_threads = a.threads;
  write.mask_noise = a.mask_noise;
  write.seed = options.seed;
  write.progress = [&bar](int done, int total) { bar.Update(done, total); };
  RETURN_IF_ERROR(WriteClutterScene(scene, a.out, write));
  std::fprintf(stderr, "synth: wrote %s: %zu Gaussians, %d objects, %zu views of %dx%d in %.1f s\n",
               a.out.c_str(), scene.cloud.size(), options.objects, scene.cameras.size(),
               options.width, options.height, watch.ElapsedSeconds());
  if (a.json) {
    nlohmann::json j = {{"scene", a.out},
                        {"gaussians", scene.cloud.size()},
                        {"objects", options.objects},
                        {"views", scene.cameras.size()},
                        {"seconds", watch.ElapsedSeconds()}};
    PrintJsonLine(j.dump());
  }
  return absl::OkStatus();
}

}  // namespace

void AddSynthCommand(CLI::App& app, Action* action) {
  auto args = std::make_shared<SynthArgs>();
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
  cmd->callback([args, action] { *action = [args] { return RunSynth(*args); }; });
}

}  // namespace instascene::cli
