#include "clients/cli/bench_complete.h"

#include <sys/resource.h>

#include <cmath>
#include <cstdio>
#include <random>

#include <nlohmann/json.hpp>

#include "common/core/status.h"
#include "common/core/timer.h"
#include "common/geometry/rigid.h"
#include "common/raster/rasterizer.h"
#include "common/synth/primitives.h"
#include "common/synth/surfels.h"
#include "services/generation/completion.h"

namespace instascene::cli {

namespace {

// A textured bottle (radius 5 cm, 25 cm) of `args.gaussians` surfels on a 1.5 m table, seen by 10
// cameras on its front half (azimuth -70..70 degrees): the surfels facing away from every camera
// are dropped, as a capture would have nothing there (labels: table 0, bottle 1). The views'
// images are renders of the complete scene.
struct BottleScene {
  GaussianCloud scene;
  std::vector<uint32_t> labels;
  std::vector<PinholeCamera> cameras;
  std::vector<Image> images;
  size_t table = 0;  // table surfels (the first ones)
};
absl::StatusOr<BottleScene> MakeBottleScene(const CompleteBenchArgs& args) {
  std::mt19937_64 rng(args.seed);
  Appearance table_look, bottle_look;
  bottle_look.pattern = TexturePattern::kStripes;
  bottle_look.specular = 0.05f;
  GaussianCloud all;
  all.num_scales = 2;
  all.sh_degree = 1;
  AppendSurfels(MakeRectangle(1.5f, 1.5f, 8, 8), 6000, table_look, SurfelSampling{}, rng, &all);
  const size_t table = all.size();
  ShapeSpec bottle;
  bottle.kind = ShapeKind::kBottle;
  bottle.size = {0.05f, 0, 0.25f};
  AppendSurfels(MakeShapeMesh(bottle, 48), static_cast<size_t>(args.gaussians), bottle_look,
                SurfelSampling{}, rng, &all);
  std::vector<PinholeCamera> cameras;
  for (int k = 0; k < 10; ++k) {
    cameras.push_back(OrbitCamera({0, 0, 0.1}, {0, 0, 1}, 0.9, -70.0 + 140.0 * k / 9.0,
                                  20.0 + 10 * (k % 3), args.width, args.height, 55.0));
  }
  std::vector<Image> images;
  for (const PinholeCamera& c : cameras) {
    RenderOptions o;
    o.num_threads = args.threads;
    ASSIGN_OR_RETURN(RenderResult r, Render(all, c, o));
    images.push_back(Image{r.width, r.height, 3, std::move(r.color)});
  }
  std::vector<uint32_t> keep, labels;
  for (uint32_t g = 0; g < all.size(); ++g) {
    bool seen = g < table;
    const Eigen::Vector3d p(all.positions[3 * g], all.positions[3 * g + 1],
                            all.positions[3 * g + 2]);
    const float* q = &all.rotations[4 * g];
    const Eigen::Vector3d n = RotationFromQuaternionWxyz(q[0], q[1], q[2], q[3]).col(2);
    for (const PinholeCamera& c : cameras) seen = seen || n.dot(c.CenterInWorld() - p) > 0;
    if (!seen) continue;
    keep.push_back(g);
    labels.push_back(g < table ? 0 : 1);
  }
  return BottleScene{all.Subset(keep), std::move(labels), std::move(cameras), std::move(images),
                     table};
}

// The completion's defaults but for the benchmark's refinement, threads and seed; the views'
// images come from the bench scene (which must outlive the options).
generation::CompletionOptions BenchOptions(const CompleteBenchArgs& args,
                                           const BottleScene& bench) {
  generation::CompletionOptions options;
  options.refinement.iterations = args.iterations;
  options.refinement.lambda_normal = args.lambda_normal;
  options.num_threads = args.threads;
  options.seed = args.seed;
  options.load_view = [&bench](int view) -> absl::StatusOr<Image> { return bench.images.at(view); };
  return options;
}

}  // namespace

absl::Status BenchComplete(const CompleteBenchArgs& args) {
  if (args.gaussians < 1000 || args.gaussians > 2'000'000 || args.iterations < 0 ||
      !(args.lambda_normal >= 0)) {
    return absl::InvalidArgumentError(
        "bench complete: --gaussians in [1000, 2e6], iterations >= 0, lambda-normal >= 0");
  }
  ASSIGN_OR_RETURN(const BottleScene bench, MakeBottleScene(args));
  const GaussianCloud& scene = bench.scene;
  const std::vector<PinholeCamera>& cameras = bench.cameras;
  const std::vector<uint32_t>& labels = bench.labels;
  const size_t table = bench.table;
  const generation::CompletionOptions options = BenchOptions(args, bench);
  std::fprintf(stderr,
               "bench complete: a bottle of %zu observed surfels on a table, %zu views of %dx%d, "
               "%d refinement iterations, %d threads\n",
               scene.size() - table, cameras.size(), args.width, args.height, args.iterations,
               args.threads);
  Stopwatch watch;
  ASSIGN_OR_RETURN(generation::CompletedObject object,
                   generation::CompleteObject(cameras, scene, labels, 1, options));
  const double total = watch.ElapsedSeconds();
  const nlohmann::json& r = object.manifest["refinement"];
  const double refine_s = r.value("seconds", 0.0);
  struct rusage usage;
  getrusage(RUSAGE_SELF, &usage);
  const double peak_mb = usage.ru_maxrss / 1024.0;
  std::fprintf(stderr,
               "complete: %zu observed + %zu completed Gaussians; total %.1f s, refinement %.1f s "
               "(%.2f ms per iteration, %d real + %d generated views), peak RSS %.0f MB\n",
               object.raw.size(), object.object.size() - object.raw.size(), total, refine_s,
               args.iterations ? 1000.0 * refine_s / args.iterations : 0.0,
               r.value("real_views", 0), r.value("generated_views", 0), peak_mb);
  if (args.json) {
    std::printf("%s\n",
                nlohmann::json({{"observed", object.raw.size()},
                                {"completed", object.object.size() - object.raw.size()},
                                {"gaussians", object.object.size()},
                                {"iterations", args.iterations},
                                {"total_s", total},
                                {"refinement_s", refine_s},
                                {"ms_per_iteration",
                                 args.iterations ? 1000.0 * refine_s / args.iterations : 0.0},
                                {"initial_loss", r.value("initial_loss", 0.0)},
                                {"final_loss", r.value("final_loss", 0.0)},
                                {"peak_rss_mb", peak_mb}})
                    .dump()
                    .c_str());
  }
  return absl::OkStatus();
}

}  // namespace instascene::cli
