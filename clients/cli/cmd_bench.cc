// `instascene bench`: end-to-end benchmarks on synthetic scenes (medians, never timed tests).
#include <cstdio>

#include <nlohmann/json.hpp>

#include "absl/strings/str_cat.h"
#include "clients/cli/bench_complete.h"
#include "clients/cli/cli.h"
#include "common/core/parallel.h"
#include "common/core/statistics.h"
#include "common/core/status.h"
#include "common/core/timer.h"
#include "common/eval/click_eval.h"
#include "common/raster/rasterizer.h"
#include "common/scene/image_io.h"
#include "common/synth/cluttered_scene.h"
#include "common/synth/scene_writer.h"
#include "services/decomposition/decompose.h"
#include "services/training/feature_field.h"
#include "services/training/segmentation.h"

#include <sys/resource.h>

#include <filesystem>

namespace instascene::cli {
namespace {

struct BenchArgs {
  std::string what;
  std::string preset = "medium", work;
  int64_t gaussians = 1'000'000;
  bool gaussians_set = false, views_set = false;
  int iterations = 0;
  int width = 1280, height = 720, frames = 5, threads = 0, objects = 40;
  double lambda_normal = 0.05;
  uint64_t seed = 1;
  bool json = false;
};

// Per frame: the plain render's time and stages, the traced render's and the tracker's (w > 0.1);
// per-frame means of the counts.
struct RasterFrames {
  std::vector<double> ms, trace_ms, pre, bin, blend, trace_blend, trace_assembly, tracker_ms;
  double visible = 0, pairs = 0, blended = 0, evaluated = 0, entries = 0, tracker_entries = 0;
};
absl::StatusOr<RasterFrames> MeasureFrames(const ClutterScene& scene, const BenchArgs& args) {
  RasterWorkspace workspace;  // reused across frames, as a long-running worker would
  RenderOptions plain;
  plain.depth = true;
  plain.workspace = &workspace;
  plain.num_threads = args.threads;
  RenderOptions traced = plain;
  traced.trace.enabled = true;
  RenderOptions tracker = traced;  // the decomposition tracker's rule: keep w > 0.1 only
  tracker.trace.min_weight = 0.1f;
  RasterFrames f;
  // Untimed warm-up frames (thread pool start, first-touch of the reused buffers).
  RenderResult r, t, k;  // reused across frames
  RETURN_IF_ERROR(RenderInto(scene.cloud, scene.cameras[0], plain, &r));
  RETURN_IF_ERROR(RenderInto(scene.cloud, scene.cameras[0], traced, &t));
  for (const PinholeCamera& camera : scene.cameras) {
    RETURN_IF_ERROR(RenderInto(scene.cloud, camera, plain, &r));
    f.ms.push_back(r.stats.total_ms);
    f.pre.push_back(r.stats.preprocess_ms);
    f.bin.push_back(r.stats.binning_ms);
    f.blend.push_back(r.stats.blend_ms);
    f.visible += static_cast<double>(r.stats.visible_gaussians) / args.frames;
    f.pairs += static_cast<double>(r.stats.gaussian_tile_pairs) / args.frames;
    f.blended += static_cast<double>(r.stats.blended_fragments) / args.frames;
    f.evaluated += static_cast<double>(r.stats.evaluated_fragments) / args.frames;
    RETURN_IF_ERROR(RenderInto(scene.cloud, camera, traced, &t));
    f.trace_ms.push_back(t.stats.total_ms);
    f.trace_blend.push_back(t.stats.blend_ms);
    f.trace_assembly.push_back(t.stats.trace_assembly_ms);
    f.entries += static_cast<double>(t.trace.entries.size()) / args.frames;
    RETURN_IF_ERROR(RenderInto(scene.cloud, camera, tracker, &k));
    f.tracker_ms.push_back(k.stats.total_ms);
    f.tracker_entries += static_cast<double>(k.trace.entries.size()) / args.frames;
  }
  return f;
}

// The --json line of `bench raster`.
nlohmann::json RasterJson(const BenchArgs& args, size_t gaussians, const RasterFrames& f) {
  const double median = Median(f.ms), trace_median = Median(f.trace_ms);
  return {{"benchmark", "raster"},
          {"gaussians", gaussians},
          {"width", args.width},
          {"height", args.height},
          {"frames", args.frames},
          {"threads", args.threads > 0 ? args.threads : DefaultThreadCount()},
          {"median_ms", median},
          {"trace_median_ms", trace_median},
          {"preprocess_ms", Median(f.pre)},
          {"binning_ms", Median(f.bin)},
          {"blend_ms", Median(f.blend)},
          {"visible_gaussians", f.visible},
          {"gaussian_tile_pairs", f.pairs},
          {"evaluated_fragments", f.evaluated},
          {"blended_fragments", f.blended},
          {"pairs_per_s", f.pairs / median * 1e3},
          {"blended_fragments_per_s", f.blended / median * 1e3},
          {"trace_entries", f.entries},
          {"trace_blend_ms", Median(f.trace_blend)},
          {"trace_assembly_ms", Median(f.trace_assembly)},
          {"tracker_trace_median_ms", Median(f.tracker_ms)},
          {"tracker_trace_entries", f.tracker_entries}};
}

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
  std::fprintf(
      stderr,
      "bench raster: scene of %zu Gaussians built in %.1f s; %d frames of %dx%d, %d threads\n",
      scene.cloud.size(), build.ElapsedSeconds(), args.frames, args.width, args.height,
      args.threads > 0 ? args.threads : DefaultThreadCount());
  ASSIGN_OR_RETURN(const RasterFrames f, MeasureFrames(scene, args));
  const double median = Median(f.ms), trace_median = Median(f.trace_ms);
  std::fprintf(stderr,
               "bench raster: median %.1f ms/frame (preprocess %.1f, binning %.1f, blend %.1f); "
               "traced %.1f ms (%.2fx; blend %.1f, assembly %.1f)\n"
               "  %.0f visible Gaussians, %.0f Gaussian-tile pairs, %.0f evaluated and %.0f "
               "blended fragments per frame; "
               "%.1f M pairs/s, %.1f M blended fragments/s; %.0f trace entries per frame\n"
               "  tracker trace (w > 0.1): %.1f ms (%.2fx), %.0f entries per frame\n",
               median, Median(f.pre), Median(f.bin), Median(f.blend), trace_median,
               trace_median / median, Median(f.trace_blend), Median(f.trace_assembly), f.visible,
               f.pairs, f.evaluated, f.blended, f.pairs / median / 1e3, f.blended / median / 1e3,
               f.entries, Median(f.tracker_ms), Median(f.tracker_ms) / median, f.tracker_entries);
  if (args.json) PrintJsonLine(RasterJson(args, scene.cloud.size(), f).dump());
  return absl::OkStatus();
}

// Peak resident set size of this process, bytes.
double PeakRssBytes() {
  struct rusage usage;
  getrusage(RUSAGE_SELF, &usage);
  return static_cast<double>(usage.ru_maxrss) * 1024.0;
}

// The preset scene of a pipeline benchmark, generated and written to args.work (or a temp folder).
absl::StatusOr<std::pair<ClutterScene, std::string>> BenchScene(const BenchArgs& args,
                                                                const std::string& tag,
                                                                ClutterOptions* options) {
  ASSIGN_OR_RETURN(*options, ClutterPreset(args.preset));
  options->seed = args.seed;
  if (args.gaussians_set) options->gaussians = static_cast<size_t>(args.gaussians);
  if (args.views_set) options->views = args.frames;
  const std::string dir = args.work.empty() ? (std::filesystem::temp_directory_path() /
                                               ("instascene-bench-" + tag + "-" + args.preset))
                                                  .string()
                                            : args.work;
  ASSIGN_OR_RETURN(ClutterScene scene, GenerateClutterScene(*options));
  SceneWriteOptions write;
  write.num_threads = args.threads;
  RETURN_IF_ERROR(WriteClutterScene(scene, dir, write));
  return std::make_pair(std::move(scene), dir);
}

absl::Status BenchDecompose(const BenchArgs& args) {
  ClutterOptions options;
  Stopwatch build;
  ASSIGN_OR_RETURN(auto generated, BenchScene(args, "decompose", &options));
  const auto& [scene, dir] = generated;
  std::fprintf(stderr,
               "bench decompose: scene %s (%zu Gaussians, %zu views of %dx%d, medium noise) "
               "written in %.1f s\n",
               dir.c_str(), scene.cloud.size(), scene.cameras.size(), options.width, options.height,
               build.ElapsedSeconds());
  ASSIGN_OR_RETURN(Scene read, ReadScene(dir));
  const double rss_before = PeakRssBytes();
  decomposition::DecompositionOptions dopt;
  dopt.num_threads = args.threads;
  Stopwatch watch;
  ASSIGN_OR_RETURN(decomposition::DecompositionResult result,
                   decomposition::Decompose(read, scene.cloud, dopt));
  const double seconds = watch.ElapsedSeconds();
  RETURN_IF_ERROR(
      decomposition::WriteDecomposition(dir + "/decomposition", read, scene.cloud, result));
  ASSIGN_OR_RETURN(ClickEvaluation eval,
                   EvaluateResultDirectory(dir, dir + "/decomposition", ClickEvalOptions{}));
  const double peak = PeakRssBytes();
  std::fprintf(stderr,
               "bench decompose: %.1f s (tracking %.1f, clustering %.2f, post-processing %.1f); "
               "%zu trackers, %zu "
               "instances; peak RSS %.0f MB (before decomposing: %.0f MB); mIoU %.3f, 3D precision "
               "%.3f recall %.3f\n",
               seconds, result.tracking_seconds, result.clustering_seconds, result.post_seconds,
               result.trackers.trackers.size(), result.instances.size(), peak / 1e6,
               rss_before / 1e6, eval.miou, eval.instances.precision, eval.instances.recall);
  if (args.json) {
    PrintJsonLine(nlohmann::json({{"benchmark", "decompose"},
                                  {"preset", args.preset},
                                  {"gaussians", scene.cloud.size()},
                                  {"views", scene.cameras.size()},
                                  {"seconds", seconds},
                                  {"tracking_s", result.tracking_seconds},
                                  {"clustering_s", result.clustering_seconds},
                                  {"post_s", result.post_seconds},
                                  {"trackers", result.trackers.trackers.size()},
                                  {"instances", result.instances.size()},
                                  {"peak_rss_mb", peak / 1e6},
                                  {"miou", eval.miou},
                                  {"precision_3d", eval.instances.precision},
                                  {"recall_3d", eval.instances.recall}})
                      .dump());
  }
  return absl::OkStatus();
}

absl::Status BenchTrain(const BenchArgs& args) {
  ClutterOptions options;
  ASSIGN_OR_RETURN(auto generated, BenchScene(args, "train", &options));
  const auto& [scene, dir] = generated;
  ASSIGN_OR_RETURN(Scene read, ReadScene(dir));
  decomposition::DecompositionOptions dopt;
  dopt.num_threads = args.threads;
  ASSIGN_OR_RETURN(decomposition::DecompositionResult coarse,
                   decomposition::Decompose(read, scene.cloud, dopt));
  RETURN_IF_ERROR(
      decomposition::WriteDecomposition(dir + "/decomposition", read, scene.cloud, coarse));
  training::TrainingOptions topt;
  topt.num_threads = args.threads;
  if (args.iterations > 0) topt.iterations = args.iterations;
  Stopwatch prepare;
  ASSIGN_OR_RETURN(training::TrainingData data,
                   training::PrepareTraining(read, scene.cloud, dir + "/decomposition", topt));
  const double prepare_s = prepare.ElapsedSeconds();
  ASSIGN_OR_RETURN(training::TrainingResult trained, training::TrainFeatures(data, topt));
  const SegmentationResult result = training::TrainedResult(
      trained, data, scene.cloud, topt.feature_dim, training::SegmentOptions{});
  RETURN_IF_ERROR(WriteResult(dir + "/segmentation", result, scene.cloud));
  ASSIGN_OR_RETURN(ClickEvaluation eval,
                   EvaluateResultDirectory(dir, dir + "/segmentation", ClickEvalOptions{}));
  const double peak = PeakRssBytes();
  std::fprintf(stderr,
               "bench train: %zu Gaussians, %zu views: pixel pools traced in %.1f s; %d steps in "
               "%.1f s (%.1f steps/s); "
               "total %.1f s; peak RSS %.0f MB (whole process); click mIoU %.3f\n",
               scene.cloud.size(), scene.cameras.size(), prepare_s, topt.iterations,
               trained.seconds, topt.iterations / trained.seconds, prepare_s + trained.seconds,
               peak / 1e6, eval.miou);
  if (args.json) {
    PrintJsonLine(nlohmann::json({{"benchmark", "train"},
                                  {"preset", args.preset},
                                  {"gaussians", scene.cloud.size()},
                                  {"views", scene.cameras.size()},
                                  {"iterations", topt.iterations},
                                  {"prepare_s", prepare_s},
                                  {"train_s", trained.seconds},
                                  {"steps_per_s", topt.iterations / trained.seconds},
                                  {"total_s", prepare_s + trained.seconds},
                                  {"peak_rss_mb", peak / 1e6},
                                  {"miou", eval.miou}})
                      .dump());
  }
  return absl::OkStatus();
}

absl::Status RunBench(const BenchArgs& a) {
  if (a.what == "decompose") return BenchDecompose(a);
  if (a.what == "train") return BenchTrain(a);
  if (a.what != "complete") return BenchRaster(a);
  CompleteBenchArgs c;
  if (a.gaussians_set) c.gaussians = a.gaussians;
  if (a.iterations > 0) c.iterations = a.iterations;
  if (a.width != 1280) c.width = a.width;
  if (a.height != 720) c.height = a.height;
  c.threads = a.threads;
  c.lambda_normal = a.lambda_normal;
  c.seed = a.seed;
  c.json = a.json;
  return BenchComplete(c);
}

}  // namespace

void AddBenchCommand(CLI::App& app, Action* action) {
  auto args = std::make_shared<BenchArgs>();
  CLI::App* cmd =
      app.add_subcommand("bench", "Benchmarks on synthetic scenes (medians over frames)");
  cmd->add_option(
         "what", args->what,
         "raster (color+depth, and with tracing), decompose or train (preset scene end to end), "
         "complete (one object: completion + joint refinement)")
      ->required()
      ->check(CLI::IsMember({"raster", "trace", "decompose", "train", "complete"}));
  cmd->add_option("--iterations", args->iterations,
                  "train: optimisation steps (default: the training default); complete: "
                  "refinement iterations (default 2000)");
  cmd->add_option("--preset", args->preset, "decompose: scene preset (default medium)");
  cmd->add_option("--work", args->work,
                  "decompose: where to write the generated scene (default: a temp folder)");
  cmd->add_option_function<int64_t>(
      "--gaussians",
      [args](int64_t v) {
        args->gaussians = v;
        args->gaussians_set = true;
      },
      "Scene size (raster default 1000000; decompose: the preset's; complete: the object's "
      "surfels before the never-seen ones are dropped, default 25000: ~20k stay)");
  cmd->add_option("--width", args->width, "Frame width, px (default 1280; complete: 640)");
  cmd->add_option("--height", args->height, "Frame height, px (default 720; complete: 480)");
  cmd->add_option_function<int>(
         "--frames",
         [args](int v) {
           args->frames = v;
           args->views_set = true;
         },
         "raster: timed frames, each from another view (default 5); decompose: views (preset's)")
      ->check(CLI::Range(1, 1000));
  cmd->add_option("--objects", args->objects, "Objects in the scene (default 40)");
  cmd->add_option("--lambda-normal", args->lambda_normal,
                  "complete: the refinement's depth-normal consistency weight (default 0.05; 0 = "
                  "off)");
  cmd->add_option("--threads", args->threads, "Threads (0 = all cores)");
  cmd->add_option("--seed", args->seed, "Scene seed");
  cmd->add_flag("--json", args->json, "Print the figures as one JSON line (last stdout line)");
  cmd->callback([args, action] { *action = [args] { return RunBench(*args); }; });
}

}  // namespace instascene::cli
