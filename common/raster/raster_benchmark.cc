// Micro-benchmarks of the rasterizer's hot paths on a synthetic cluttered scene
// (run: build/common/raster/raster_benchmark; `make bench` runs them with 5 repetitions).
#include <benchmark/benchmark.h>

#include <algorithm>
#include <bit>
#include <map>
#include <random>
#include <tuple>
#include <vector>

#include "common/raster/depth_sort.h"
#include "common/raster/projection.h"
#include "common/raster/rasterizer.h"
#include "common/raster/surfel_backward.h"
#include "common/raster/tile_backward.h"
#include "common/splat/gaussian_ply.h"
#include "common/splat/sh.h"
#include "common/synth/cluttered_scene.h"
#include "common/synth/primitives.h"
#include "common/synth/surfels.h"

namespace instascene {
namespace {

const ClutterScene& Scene(size_t gaussians, int width, int height) {
  static std::map<std::tuple<size_t, int, int>, ClutterScene> cache;
  auto key = std::make_tuple(gaussians, width, height);
  auto it = cache.find(key);
  if (it == cache.end()) {
    ClutterOptions o;
    o.gaussians = gaussians;
    o.width = width;
    o.height = height;
    o.views = 4;
    o.objects = 20;
    it = cache.emplace(key, *GenerateClutterScene(o)).first;
  }
  return it->second;
}

// Full frame: color + depth, with a reused workspace and result (as a worker renders).
void BM_RenderColorDepth(benchmark::State& state) {
  const ClutterScene& scene = Scene(state.range(0), 640, 480);
  RasterWorkspace workspace;
  RenderOptions options;
  options.depth = true;
  options.workspace = &workspace;
  options.num_threads = static_cast<int>(state.range(1));
  RenderResult result;
  uint64_t blended = 0;
  for (auto _ : state) {
    if (!RenderInto(scene.cloud, scene.cameras[1], options, &result).ok())
      state.SkipWithError("render failed");
    blended = result.stats.blended_fragments;
  }
  state.counters["blended_fragments/s"] = benchmark::Counter(
      static_cast<double>(blended), benchmark::Counter::kIsIterationInvariantRate);
}
BENCHMARK(BM_RenderColorDepth)
    ->Args({300000, 1})
    ->Args({300000, 2})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

// The same frame with every contribution traced.
void BM_RenderTraced(benchmark::State& state) {
  const ClutterScene& scene = Scene(state.range(0), 640, 480);
  RasterWorkspace workspace;
  RenderOptions options;
  options.workspace = &workspace;
  options.trace.enabled = true;
  options.trace.min_weight = static_cast<float>(state.range(1)) / 10.0f;
  RenderResult result;
  for (auto _ : state) {
    if (!RenderInto(scene.cloud, scene.cameras[1], options, &result).ok())
      state.SkipWithError("render failed");
  }
  state.counters["entries"] = static_cast<double>(result.trace.entries.size());
}
BENCHMARK(BM_RenderTraced)
    ->Args({300000, 0})
    ->Args({300000, 1})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

// Per-Gaussian preprocessing (2DGS transform, bounding box, window, SH colour), single thread,
// in batches of 4096 as the rasterizer calls it.
void BM_ProjectSurfels(benchmark::State& state) {
  const ClutterScene& scene = Scene(300000, 640, 480);
  const ProjectionParams params =
      MakeProjectionParams(scene.cameras[1], RenderOptions{}, scene.cloud.sh_degree);
  constexpr size_t kBatch = 4096;
  std::vector<ProjectedSplat> out(kBatch);
  std::vector<uint8_t> visible(kBatch);
  size_t first = 0;
  for (auto _ : state) {
    ProjectSurfels(scene.cloud, first, kBatch, params, out.data(), visible.data());
    benchmark::DoNotOptimize(visible.data());
    first = first + 2 * kBatch <= scene.cloud.size() ? first + kBatch : 0;
  }
  state.SetItemsProcessed(state.iterations() * kBatch);
}
BENCHMARK(BM_ProjectSurfels);

// One tile's depth sort as binning meets it: state.range(0) keys of depths in [2, 6) with
// ascending Gaussian indices; arg 1 = 0: std::sort, 1: the radix sort the rasterizer uses.
void BM_SortTileKeys(benchmark::State& state) {
  const size_t n = static_cast<size_t>(state.range(0));
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> depth(2.0f, 6.0f);
  std::vector<uint64_t> input(n), keys(n), scratch(n);
  for (size_t i = 0; i < n; ++i)
    input[i] = (uint64_t{std::bit_cast<uint32_t>(depth(rng))} << 32) | (7 * i);
  for (auto _ : state) {
    keys = input;
    if (state.range(1) == 0) {
      std::sort(keys.begin(), keys.end());
    } else {
      raster_internal::SortTileKeys(keys.data(), n, scratch.data());
    }
    benchmark::DoNotOptimize(keys.data());
  }
  state.SetItemsProcessed(state.iterations() * static_cast<int64_t>(n));
}
BENCHMARK(BM_SortTileKeys)->ArgsProduct({{64, 200, 400, 600, 5000}, {0, 1}});

// The refinement kernel (surfel_backward.h) on one object of `count` surfels (a bottle, SH 1) seen
// from a ring camera at 256x256: the forward the refinement renders, its backward, and the
// production rasterizer's forward on the same view for comparison.
struct RingObject {
  GaussianCloud cloud;
  PinholeCamera camera;
};
const RingObject& Object(size_t count) {
  static std::map<size_t, RingObject> cache;
  auto it = cache.find(count);
  if (it == cache.end()) {
    RingObject o;
    o.cloud.num_scales = 2;
    o.cloud.sh_degree = 1;
    std::mt19937_64 rng(3);
    Appearance appearance;
    appearance.specular = 0.05f;
    AppendSurfels(MakeShapeMesh({ShapeKind::kBottle, {0.05f, 0, 0.25f}}), count, appearance,
                  SurfelSampling{}, rng, &o.cloud);
    o.camera = OrbitCamera({0, 0, 0.12}, {0, 0, 1}, 0.45, 30, 30, 256, 256, 49.1);
    it = cache.emplace(count, std::move(o)).first;
  }
  return it->second;
}
void BM_SurfelForwardDifferentiable(benchmark::State& state) {
  const RingObject& o = Object(state.range(0));
  for (auto _ : state) {
    auto image = RenderSurfelsDifferentiable(o.cloud, o.camera, {});
    benchmark::DoNotOptimize(image);
  }
}
BENCHMARK(BM_SurfelForwardDifferentiable)->Arg(20000)->Unit(benchmark::kMillisecond)->UseRealTime();
void BM_SurfelBackward(benchmark::State& state) {
  const RingObject& o = Object(state.range(0));
  const std::vector<float> d_color(3 * 256 * 256, 0.1f), d_alpha(256 * 256, 0.1f);
  for (auto _ : state) {
    auto grads = SurfelBackward(o.cloud, o.camera, {}, d_color, d_alpha);
    benchmark::DoNotOptimize(grads);
  }
}
BENCHMARK(BM_SurfelBackward)->Arg(20000)->Unit(benchmark::kMillisecond)->UseRealTime();
void BM_RasterizerForwardRing(benchmark::State& state) {
  const RingObject& o = Object(state.range(0));
  RenderOptions options;
  for (auto _ : state) {
    auto image = Render(o.cloud, o.camera, options);
    benchmark::DoNotOptimize(image);
  }
}
BENCHMARK(BM_RasterizerForwardRing)->Arg(20000)->Unit(benchmark::kMillisecond)->UseRealTime();

// The fast backward (tile_backward.h): the forward it needs (production render + full trace with
// transmittance) and the backward itself, on the same view.
void BM_TileForwardForBackward(benchmark::State& state) {
  const RingObject& o = Object(state.range(0));
  RenderOptions options;
  for (auto _ : state) {
    auto image = RenderForBackward(o.cloud, o.camera, options);
    benchmark::DoNotOptimize(image);
  }
}
BENCHMARK(BM_TileForwardForBackward)->Arg(20000)->Unit(benchmark::kMillisecond)->UseRealTime();
void BM_TileBackward(benchmark::State& state) {
  const RingObject& o = Object(state.range(0));
  RenderOptions options;
  auto forward = RenderForBackward(o.cloud, o.camera, options);
  const std::vector<float> d_color(3 * 256 * 256, 0.1f), d_alpha(256 * 256, 0.1f);
  for (auto _ : state) {
    auto grads = TileBackward(o.cloud, o.camera, options, *forward, d_color, d_alpha);
    benchmark::DoNotOptimize(grads);
  }
}
BENCHMARK(BM_TileBackward)->Arg(20000)->Unit(benchmark::kMillisecond)->UseRealTime();
// With the depth-normal consistency's images too: the forward renders median depth and normals,
// the backward takes all four adjoints.
void BM_TileForwardForBackwardNormalDepth(benchmark::State& state) {
  const RingObject& o = Object(state.range(0));
  RenderOptions options;
  options.depth = options.normal = true;
  for (auto _ : state) {
    auto image = RenderForBackward(o.cloud, o.camera, options);
    benchmark::DoNotOptimize(image);
  }
}
BENCHMARK(BM_TileForwardForBackwardNormalDepth)
    ->Arg(20000)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();
void BM_TileBackwardNormalDepth(benchmark::State& state) {
  const RingObject& o = Object(state.range(0));
  RenderOptions options;
  options.depth = options.normal = true;
  auto forward = RenderForBackward(o.cloud, o.camera, options);
  const std::vector<float> d_rgb(3 * 256 * 256, 0.1f), d_one(256 * 256, 0.1f);
  const ImageAdjoints adjoints{d_rgb, d_one, d_rgb, d_one};
  for (auto _ : state) {
    auto grads = TileBackward(o.cloud, o.camera, options, *forward, adjoints);
    benchmark::DoNotOptimize(grads);
  }
}
BENCHMARK(BM_TileBackwardNormalDepth)->Arg(20000)->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_EvalShDegree3(benchmark::State& state) {
  float coeffs[48];
  for (int k = 0; k < 48; ++k) coeffs[k] = 0.01f * k;
  float rgb[3];
  float x = 0.3f;
  for (auto _ : state) {
    EvalShColor(3, coeffs, x, 0.5f, 0.81f, rgb);
    benchmark::DoNotOptimize(rgb);
    x = -x;
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_EvalShDegree3);

void BM_ParsePly(benchmark::State& state) {
  const std::string bytes = EncodeGaussianPly(Scene(300000, 640, 480).cloud);
  for (auto _ : state) {
    absl::StatusOr<GaussianCloud> cloud = ParseGaussianPly(bytes, "bench");
    benchmark::DoNotOptimize(cloud);
  }
  state.SetBytesProcessed(static_cast<int64_t>(state.iterations() * bytes.size()));
}
BENCHMARK(BM_ParsePly)->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace instascene

BENCHMARK_MAIN();
