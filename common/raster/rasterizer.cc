#include "common/raster/rasterizer.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <bit>
#include <cmath>

#include "absl/strings/str_cat.h"
#include "common/core/parallel.h"
#include "common/core/status.h"
#include "common/core/timer.h"
#include "common/raster/depth_sort.h"
#include "common/raster/projection.h"
#include "common/raster/tile_blend.h"
#include "common/raster/trace_assembler.h"

namespace instascene {
namespace {

using raster_internal::BlendTile;
using raster_internal::FrameContext;
using raster_internal::TileCounters;
using raster_internal::TileState;
using raster_internal::TileTrace;
using raster_internal::TraceAssembler;

using BlendFn = void (*)(const FrameContext&, int, TileState&, RenderResult&, TileCounters&,
                         TileTrace*);

using raster_internal::TraceMode;

template <bool kSurfel, TraceMode kMode>
BlendFn PickFeatures(bool features) {
  return features ? BlendTile<kSurfel, kMode, true> : BlendTile<kSurfel, kMode, false>;
}

// Full traces without transmittance append 8 lanes at a time; pixel subsets and transmittance
// take the scalar path.
template <bool kSurfel>
BlendFn PickBlend(const TraceOptions& trace, bool features) {
  if (!trace.enabled) return PickFeatures<kSurfel, TraceMode::kNone>(features);
  if (trace.pixels.empty() && !trace.transmittance)
    return PickFeatures<kSurfel, TraceMode::kVector>(features);
  return PickFeatures<kSurfel, TraceMode::kScalar>(features);
}

// Bins visible splats into per-tile key lists, in parallel over fixed chunks of Gaussians (the
// chunking depends only on n, so the output is the same for any thread count). Within a tile,
// keys are then sorted: centre depth first, Gaussian index for ties (the stable CUDA radix sort
// over Gaussian-ordered input gives the same order; so does SortTileKeys, a stable radix sort).
void BinSplats(const std::vector<ProjectedSplat>& splats, const std::vector<uint8_t>& visible,
               const ProjectionParams& params, RasterWorkspace* ws) {
  const size_t n = splats.size();
  const int num_tiles = params.tiles_x * params.tiles_y;
  const size_t chunk = std::max<size_t>(16384, (n + 63) / 64);
  const size_t num_chunks = (n + chunk - 1) / chunk;
  std::vector<uint64_t>& cursor = ws->chunk_cursors;
  cursor.assign(num_chunks * num_tiles, 0);
  auto for_each_pair = [&](size_t c, auto&& fn) {
    for (size_t i = c * chunk; i < std::min(n, (c + 1) * chunk); ++i) {
      if (!visible[i]) continue;
      const int32_t* t = splats[i].tiles;
      for (int ty = t[2]; ty < t[3]; ++ty) {
        for (int tx = t[0]; tx < t[1]; ++tx) fn(i, static_cast<size_t>(ty) * params.tiles_x + tx);
      }
    }
  };
  tbb::parallel_for(size_t{0}, num_chunks, [&](size_t c) {
    uint64_t* counts = &cursor[c * num_tiles];
    for_each_pair(c, [&](size_t, size_t tile) { ++counts[tile]; });
  });
  ws->tile_offsets.assign(num_tiles + 1, 0);
  uint64_t running = 0;
  for (int t = 0; t < num_tiles; ++t) {
    ws->tile_offsets[t] = running;
    for (size_t c = 0; c < num_chunks; ++c) {
      const uint64_t count = cursor[c * num_tiles + t];
      cursor[c * num_tiles + t] = running;
      running += count;
    }
  }
  ws->tile_offsets[num_tiles] = running;
  ws->keys.resize(running);
  tbb::parallel_for(size_t{0}, num_chunks, [&](size_t c) {
    uint64_t* next = &cursor[c * num_tiles];
    for_each_pair(c, [&](size_t i, size_t tile) {
      ws->keys[next[tile]++] = (uint64_t{std::bit_cast<uint32_t>(splats[i].depth)} << 32) | i;
    });
  });
  tbb::parallel_for(0, num_tiles, [&](int t) {
    thread_local std::vector<uint64_t> scratch;
    const uint64_t begin = ws->tile_offsets[t], size = ws->tile_offsets[t + 1] - begin;
    if (scratch.size() < size) scratch.resize(size);
    raster_internal::SortTileKeys(ws->keys.data() + begin, size, scratch.data());
  });
}

}  // namespace

RasterWorkspace::RasterWorkspace() = default;
RasterWorkspace::~RasterWorkspace() = default;

SplatModel ResolveModel(const GaussianCloud& cloud, SplatModel requested) {
  if (requested != SplatModel::kAuto) return requested;
  return cloud.num_scales == 2 ? SplatModel::kSurfel2d : SplatModel::kEllipsoid3d;
}

absl::Status RenderOptions::Validate() const {
  if (feature_dim < 0 || (feature_dim > 0 && features == nullptr)) {
    return absl::InvalidArgumentError("feature_dim > 0 needs a feature buffer");
  }
  if (!(near_plane > 0.0f) || !(scale_modifier > 0.0f)) {
    return absl::InvalidArgumentError("near_plane and scale_modifier must be positive");
  }
  for (size_t i = 1; i < trace.pixels.size(); ++i) {
    if (trace.pixels[i] <= trace.pixels[i - 1]) {
      return absl::InvalidArgumentError("trace.pixels must be strictly increasing");
    }
  }
  return absl::OkStatus();
}

absl::StatusOr<RenderResult> Render(const GaussianCloud& cloud, const PinholeCamera& camera,
                                    const RenderOptions& options) {
  RenderResult result;
  RETURN_IF_ERROR(RenderInto(cloud, camera, options, &result));
  return result;
}

namespace {

absl::Status CheckRenderInputs(const GaussianCloud& cloud, const PinholeCamera& camera,
                               const RenderOptions& options, bool surfel) {
  RETURN_IF_ERROR(camera.Validate());
  RETURN_IF_ERROR(options.Validate());
  if (surfel != (cloud.num_scales == 2)) {
    return absl::InvalidArgumentError(absl::StrCat(
        "splat model ", surfel ? "2DGS surfel" : "3DGS ellipsoid", " needs a ", surfel ? 2 : 3,
        "-scale cloud, got ", cloud.num_scales, " scales (convert 3DGS with ToSurfels)"));
  }
  if (cloud.size() >= (uint64_t{1} << 32)) return absl::InvalidArgumentError("too many Gaussians");
  const size_t num_pixels = static_cast<size_t>(camera.width) * camera.height;
  if (!options.trace.pixels.empty() && options.trace.pixels.back() >= num_pixels) {
    return absl::InvalidArgumentError("trace.pixels has ids outside the image");
  }
  return absl::OkStatus();
}

// Sizes the output buffers. Every pixel of every buffer is overwritten by the blend, so reused
// buffers need no clearing.
void SizeOutputs(const PinholeCamera& camera, const RenderOptions& options, size_t n,
                 RenderResult& out) {
  const size_t num_pixels = static_cast<size_t>(camera.width) * camera.height;
  out.width = camera.width;
  out.height = camera.height;
  out.stats = RasterStats{};
  out.alpha.resize(num_pixels);
  out.num_contributors.resize(num_pixels);
  out.color.resize(options.color ? 3 * num_pixels : 0);
  out.depth.resize(options.depth ? num_pixels : 0);
  out.median_depth.resize(options.depth ? num_pixels : 0);
  out.normal.resize(options.normal ? 3 * num_pixels : 0);
  out.features.resize(num_pixels * std::max(options.feature_dim, 0));
  if (!options.trace.enabled) out.trace = ContributorTrace{};
  out.visible.assign(n, 0);
}

// 1. Projects every Gaussian into the workspace's splats (and the visibility flags).
void ProjectAll(const GaussianCloud& cloud, const ProjectionParams& params, bool surfel,
                std::vector<ProjectedSplat>& splats, std::vector<uint8_t>& visible) {
  splats.resize(cloud.size());
  tbb::parallel_for(tbb::blocked_range<size_t>(0, cloud.size(), 4096),
                    [&](const tbb::blocked_range<size_t>& r) {
                      if (surfel) {
                        ProjectSurfels(cloud, r.begin(), r.size(), params, &splats[r.begin()],
                                       &visible[r.begin()]);
                        return;
                      }
                      for (size_t i = r.begin(); i < r.end(); ++i) {
                        visible[i] = ProjectEllipsoid(cloud, i, params, &splats[i]) ? 1 : 0;
                      }
                    });
}

// 3. Blends every tile; with tracing band by band (one row of tiles), each band's lists
// scattered into the CSR while they are still in cache. Returns the assembly's milliseconds.
double BlendTiles(const FrameContext& ctx, BlendFn blend, RasterWorkspace* ws,
                  std::vector<TileCounters>& counters, RenderResult& out) {
  const ProjectionParams& params = *ctx.params;
  const RenderOptions& options = *ctx.options;
  if (!options.trace.enabled) {
    tbb::parallel_for(tbb::blocked_range<int>(0, params.tiles_x * params.tiles_y, 1),
                      [&](const tbb::blocked_range<int>& r) {
                        thread_local TileState state;
                        for (int t = r.begin(); t < r.end(); ++t)
                          blend(ctx, t, state, out, counters[t], nullptr);
                      });
    return 0;
  }
  double assembly_ms = 0;
  std::vector<TileTrace>& band = ws->tile_traces;
  band.resize(params.tiles_x);
  TraceAssembler assembler(params, options.trace, &out.trace);
  for (int ty = 0; ty < params.tiles_y; ++ty) {
    tbb::parallel_for(tbb::blocked_range<int>(0, params.tiles_x, 1),
                      [&](const tbb::blocked_range<int>& r) {
                        thread_local TileState state;
                        for (int tx = r.begin(); tx < r.end(); ++tx) {
                          const int t = ty * params.tiles_x + tx;
                          blend(ctx, t, state, out, counters[t], &band[tx]);
                        }
                      });
    Stopwatch assembly;
    assembler.AddBand(ty, band);
    assembly_ms += assembly.ElapsedMs();
  }
  assembler.Finish();
  return assembly_ms;
}

}  // namespace

absl::Status RenderInto(const GaussianCloud& cloud, const PinholeCamera& camera,
                        const RenderOptions& options, RenderResult* result) {
  Stopwatch total;
  const SplatModel model = ResolveModel(cloud, options.model);
  const bool surfel = model == SplatModel::kSurfel2d;
  RETURN_IF_ERROR(CheckRenderInputs(cloud, camera, options, surfel));
  const ProjectionParams params = MakeProjectionParams(camera, options, cloud.sh_degree);
  RenderResult& out = *result;
  SizeOutputs(camera, options, cloud.size(), out);
  RasterWorkspace local_workspace;
  RasterWorkspace* ws = options.workspace != nullptr ? options.workspace : &local_workspace;
  RunWithThreads(options.num_threads, [&] {
    Stopwatch phase;
    ProjectAll(cloud, params, surfel, ws->splats, out.visible);
    out.stats.preprocess_ms = phase.ElapsedMs();
    phase.Restart();
    // 2. Bin (Gaussian, tile) pairs and sort every tile's list front to back.
    BinSplats(ws->splats, out.visible, params, ws);
    out.stats.binning_ms = phase.ElapsedMs();
    phase.Restart();
    std::vector<uint8_t> trace_mask;
    if (options.trace.enabled && !options.trace.pixels.empty()) {
      trace_mask.assign(out.alpha.size(), 0);
      for (uint32_t pix : options.trace.pixels) trace_mask[pix] = 1;
    }
    FrameContext ctx{&options, &params, &ws->splats, &ws->keys, &ws->tile_offsets, &trace_mask, {}};
    const Eigen::Matrix3d world_from_camera = camera.camera_from_world.rotation.transpose();
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 3; ++c)
        ctx.world_from_camera[3 * r + c] = static_cast<float>(world_from_camera(r, c));
    }
    const bool features = options.feature_dim > 0;
    const BlendFn blend = surfel ? PickBlend<true>(options.trace, features)
                                 : PickBlend<false>(options.trace, features);
    std::vector<TileCounters> counters(params.tiles_x * params.tiles_y);
    const double assembly_ms = BlendTiles(ctx, blend, ws, counters, out);
    for (const TileCounters& c : counters) {
      out.stats.evaluated_fragments += c.evaluated;
      out.stats.blended_fragments += c.blended;
    }
    out.stats.gaussian_tile_pairs = ws->keys.size();
    out.stats.blend_ms = phase.ElapsedMs() - assembly_ms;
    out.stats.trace_assembly_ms = assembly_ms;
  });
  for (uint8_t v : out.visible) out.stats.visible_gaussians += v;
  out.stats.total_ms = total.ElapsedMs();
  return absl::OkStatus();
}

}  // namespace instascene
