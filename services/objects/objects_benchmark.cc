// The export's kernels on a cup of the size of a real object mesh (~70k triangles, as the TSDF
// meshes of the completion are): Qhull hull, convex decomposition, Draco glb, mass properties.
#include <benchmark/benchmark.h>

#include "services/objects/convex_decomposition.h"
#include "services/objects/convex_hull.h"
#include "services/objects/gltf_writer.h"
#include "services/objects/mass_properties.h"
#include "services/objects/testing/shapes.h"

namespace instascene::objects {
namespace {

const TriangleMesh& RealSizedCup() {
  static const TriangleMesh cup = [] {
    TriangleMesh m = testing::Cup(720, 9);  // 5 sides x 10 rings x 720 x 2 ~ 70k triangles
    for (auto& v : m.vertices) {
      v *= 0.1f;  // 20 cm
      m.colors.emplace_back(0.8f, 0.4f, 0.1f);
    }
    return m;
  }();
  return cup;
}

void BM_ConvexHull(benchmark::State& state) {
  for (auto _ : state) benchmark::DoNotOptimize(ConvexHull(RealSizedCup().vertices));
  state.counters["triangles"] = static_cast<double>(RealSizedCup().triangles.size());
}
BENCHMARK(BM_ConvexHull)->Unit(benchmark::kMillisecond);

void BM_ConvexDecomposition(benchmark::State& state) {
  ConvexDecompositionOptions options;
  options.resolution = static_cast<int>(state.range(0));
  size_t parts = 0;
  for (auto _ : state) parts = ConvexDecomposition(RealSizedCup(), options)->size();
  state.counters["parts"] = static_cast<double>(parts);
}
BENCHMARK(BM_ConvexDecomposition)->Arg(40)->Arg(64)->Unit(benchmark::kMillisecond);

void BM_DracoGlb(benchmark::State& state) {
  size_t bytes = 0;
  for (auto _ : state) bytes = EncodeDracoGlb(RealSizedCup())->bytes.size();
  state.counters["glb_bytes"] = static_cast<double>(bytes);
}
BENCHMARK(BM_DracoGlb)->Unit(benchmark::kMillisecond);

void BM_MassProperties(benchmark::State& state) {
  for (auto _ : state) benchmark::DoNotOptimize(MeshMassProperties(RealSizedCup()));
}
BENCHMARK(BM_MassProperties)->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace instascene::objects

BENCHMARK_MAIN();
