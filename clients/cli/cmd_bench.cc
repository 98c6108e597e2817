// `instascene bench`: end-to-end benchmarks on synthetic scenes (medians, never timed tests).
#include <cstdio>

#include <nlohmann/json.hpp>

#include "absl/strings/str_cat.h"
#include "clients/cli/cli.h"
#include "common/core/parallel.h"
#include "common/core/statistics.h"
#include "common/core/status.h"
#include "common/core/timer.h"
#include "common/raster/rasterizer.h"
#include "common/synth/cluttered_scene.h"

namespace instascene::cli {
namespace {

struct BenchArgs {
  std::string what;
  int64_t gaussians = 1'000'000;
  int width = 1280, height = 720, frames = 5, threads = 0, objects = 40;
  uint64_t seed = 1;
  bool json = false;
};

absl::Status BenchRaster(const BenchArgs& args) {
  ClutterOptions options;
  options.seed = args.seed;
  options.objects = args.objects;
  options.views = args.frames;
  options.width = args.width;
  options.height = args.height;
  options.gaussians = static_cast<size_t>(args.gaussians);
  Stopwatch build;
  ASSIGN_OR_RETURN(ClutterScene scene, GenerateClutterScene(options));
  std::fprintf(stderr, "bench raster: scene of %zu Gaussians built in %.1f s; %d frames of %dx%d, %d threads\n",
               scene.cloud.size(), build.ElapsedSeconds(), args.frames, args.width, args.height,
               args.threads > 0 ? args.threads : DefaultThreadCount());
  RasterWorkspace workspace;  // reused across frames, as a long-running worker would
  RenderOptions plain;
  plain.depth = true;
  plain.workspace = &workspace;
  plain.num_threads = args.threads;
  RenderOptions traced = plain;
  traced.trace.enabled = true;
  RenderOptions tracker = traced;  // the decomposition tracker's rule: keep w > 0.1 only
  tracker.trace.min_weight = 0.1f;
  std::vector<double> ms, trace_ms, pre, bin, blend, trace_blend, trace_assembly, tracker_ms;
  double pairs = 0, blended = 0, evaluated = 0, entries = 0, tracker_entries = 0;
  // Untimed warm-up frames (thread pool start, first-touch of the reused buffers).
  RenderResult r, t, k;  // reused across frames
  RETURN_IF_ERROR(RenderInto(scene.cloud, scene.cameras[0], plain, &r));
  RETURN_IF_ERROR(RenderInto(scene.cloud, scene.cameras[0], traced, &t));
  for (const PinholeCamera& camera : scene.cameras) {
    RETURN_IF_ERROR(RenderInto(scene.cloud, camera, plain, &r));
    ms.push_back(r.stats.total_ms);
    pre.push_back(r.stats.preprocess_ms);
    bin.push_back(r.stats.binning_ms);
    blend.push_back(r.stats.blend_ms);
    pairs += static_cast<double>(r.stats.gaussian_tile_pairs) / args.frames;
    blended += static_cast<double>(r.stats.blended_fragments) / args.frames;
    evaluated += static_cast<double>(r.stats.evaluated_fragments) / args.frames;
    RETURN_IF_ERROR(RenderInto(scene.cloud, camera, traced, &t));
    trace_ms.push_back(t.stats.total_ms);
    trace_blend.push_back(t.stats.blend_ms);
    trace_assembly.push_back(t.stats.trace_assembly_ms);
    entries += static_cast<double>(t.trace.entries.size()) / args.frames;
    RETURN_IF_ERROR(RenderInto(scene.cloud, camera, tracker, &k));
    tracker_ms.push_back(k.stats.total_ms);
    tracker_entries += static_cast<double>(k.trace.entries.size()) / args.frames;
  }
  const double median = Median(ms), trace_median = Median(trace_ms);
  std::fprintf(stderr,
               "bench raster: median %.1f ms/frame (preprocess %.1f, binning %.1f, blend %.1f); "
               "traced %.1f ms (%.2fx; blend %.1f, assembly %.1f)\n"
               "  %.0f Gaussian-tile pairs, %.0f evaluated and %.0f blended fragments per frame; "
               "%.1f M pairs/s, %.1f M blended fragments/s; %.0f trace entries per frame\n"
               "  tracker trace (w > 0.1): %.1f ms (%.2fx), %.0f entries per frame\n",
               median, Median(pre), Median(bin), Median(blend), trace_median, trace_median / median,
               Median(trace_blend), Median(trace_assembly), pairs,
               evaluated, blended, pairs / median / 1e3, blended / median / 1e3, entries, Median(tracker_ms),
               Median(tracker_ms) / median, tracker_entries);
  if (args.json) {
    nlohmann::json j = {{"benchmark", "raster"}, {"gaussians", scene.cloud.size()}, {"width", args.width},
                        {"height", args.height}, {"frames", args.frames},
                        {"threads", args.threads > 0 ? args.threads : DefaultThreadCount()},
                        {"median_ms", median}, {"trace_median_ms", trace_median},
                        {"preprocess_ms", Median(pre)}, {"binning_ms", Median(bin)}, {"blend_ms", Median(blend)},
                        {"gaussian_tile_pairs", pairs}, {"evaluated_fragments", evaluated},
                        {"blended_fragments", blended}, {"pairs_per_s", pairs / median * 1e3},
                        {"blended_fragments_per_s", blended / median * 1e3}, {"trace_entries", entries}, {"trace_blend_ms", Median(trace_blend)},
                        {"trace_assembly_ms", Median(trace_assembly)},
                        {"tracker_trace_median_ms", Median(tracker_ms)}, {"tracker_trace_entries", tracker_entries}};
    PrintJsonLine(j.dump());
  }
  return absl::OkStatus();
}

}  // namespace

void AddBenchCommand(CLI::App& app, Action* action) {
  auto args = std::make_shared<BenchArgs>();
  CLI::App* cmd = app.add_subcommand("bench", "Benchmarks on synthetic scenes (medians over frames)");
  cmd->add_option("what", args->what, "Which benchmark: raster (color+depth, and with full tracing)")
      ->required()
      ->check(CLI::IsMember({"raster", "trace"}));
  cmd->add_option("--gaussians", args->gaussians, "Scene size (default 1000000)");
  cmd->add_option("--width", args->width, "Frame width, px (default 1280)");
  cmd->add_option("--height", args->height, "Frame height, px (default 720)");
  cmd->add_option("--frames", args->frames, "Timed frames, each from another view (default 5)")->check(CLI::Range(1, 1000));
  cmd->add_option("--objects", args->objects, "Objects in the scene (default 40)");
  cmd->add_option("--threads", args->threads, "Threads (0 = all cores)");
  cmd->add_option("--seed", args->seed, "Scene seed");
  cmd->add_flag("--json", args->json, "Print the figures as one JSON line (last stdout line)");
  cmd->callback([args, action] {
    *action = [args]() -> absl::Status { return BenchRaster(*args); };
  });
}

}  // namespace instascene::cli
