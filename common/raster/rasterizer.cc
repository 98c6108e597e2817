#include "common/raster/rasterizer.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>

#include "absl/strings/str_cat.h"
#include "common/core/parallel.h"
#include "common/core/status.h"
#include "common/core/timer.h"
#include "common/raster/projection.h"
#include "common/raster/tile_blend.h"

namespace instascene {
namespace {

using raster_internal::BlendTile;
using raster_internal::FrameContext;
using raster_internal::TileCounters;
using raster_internal::TileState;
using raster_internal::TileTraceEntry;

using BlendFn = void (*)(const FrameContext&, int, TileState&, RenderResult&, TileCounters&);

template <bool kSurfel>
BlendFn PickBlend(bool trace, bool features) {
  if (trace) return features ? BlendTile<kSurfel, true, true> : BlendTile<kSurfel, true, false>;
  return features ? BlendTile<kSurfel, false, true> : BlendTile<kSurfel, false, false>;
}

// Builds the CSR trace from per-tile lists (each in blending order: front to back within a pixel).
// Tiles own disjoint pixels, so counting and scattering run tile-parallel without races.
void AssembleTrace(const ProjectionParams& p, const std::vector<std::vector<TileTraceEntry>>& tiles,
                   const TraceOptions& trace_options, ContributorTrace* trace) {
  const size_t num_pixels = static_cast<size_t>(p.width) * p.height;
  const bool all_pixels = trace_options.pixels.empty();
  std::vector<int64_t> slot;  // pixel -> CSR row, for a pixel subset
  if (all_pixels) {
    trace->pixels.resize(num_pixels);
    for (size_t i = 0; i < num_pixels; ++i) trace->pixels[i] = static_cast<uint32_t>(i);
  } else {
    trace->pixels = trace_options.pixels;
    slot.assign(num_pixels, -1);
    for (size_t i = 0; i < trace->pixels.size(); ++i) slot[trace->pixels[i]] = static_cast<int64_t>(i);
  }
  auto row_of = [&](size_t t, uint16_t local) -> size_t {
    const size_t tx = t % p.tiles_x, ty = t / p.tiles_x;
    const size_t pix = (ty * kTileSize + local / kTileSize) * p.width + tx * kTileSize + local % kTileSize;
    return all_pixels ? pix : static_cast<size_t>(slot[pix]);
  };
  std::vector<uint64_t> offsets(trace->pixels.size() + 1, 0);
  tbb::parallel_for(size_t{0}, tiles.size(), [&](size_t t) {
    for (const TileTraceEntry& e : tiles[t]) ++offsets[row_of(t, e.local_pixel) + 1];
  });
  for (size_t i = 1; i < offsets.size(); ++i) offsets[i] += offsets[i - 1];
  trace->entries.resize(offsets.back());
  tbb::parallel_for(size_t{0}, tiles.size(), [&](size_t t) {
    // Entries of one pixel arrive front to back; offsets[row] is that pixel's write cursor.
    for (const TileTraceEntry& e : tiles[t]) trace->entries[offsets[row_of(t, e.local_pixel)]++] = e.contribution;
  });
  // The cursors now sit at each row's end: shift back by one row to restore the starts.
  for (size_t i = offsets.size() - 1; i > 0; --i) offsets[i] = offsets[i - 1];
  offsets[0] = 0;
  trace->offsets = std::move(offsets);
}

// Bins visible splats into per-tile key lists, in parallel over fixed chunks of Gaussians (the
// chunking depends only on n, so the output is the same for any thread count). Within a tile,
// keys are then sorted: centre depth first, Gaussian index for ties (the stable CUDA radix sort
// over Gaussian-ordered input gives the same order).
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
    std::sort(ws->keys.begin() + ws->tile_offsets[t], ws->keys.begin() + ws->tile_offsets[t + 1]);
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
  Stopwatch total;
  RETURN_IF_ERROR(camera.Validate());
  RETURN_IF_ERROR(options.Validate());
  const SplatModel model = ResolveModel(cloud, options.model);
  const bool surfel = model == SplatModel::kSurfel2d;
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
  const ProjectionParams params = MakeProjectionParams(camera, options, cloud.sh_degree);
  const size_t n = cloud.size();
  RenderResult out;
  out.width = camera.width;
  out.height = camera.height;
  out.alpha.resize(num_pixels);
  out.num_contributors.resize(num_pixels);
  if (options.color) out.color.resize(3 * num_pixels);
  if (options.depth) {
    out.depth.resize(num_pixels);
    out.median_depth.resize(num_pixels);
  }
  if (options.normal) out.normal.resize(3 * num_pixels);
  if (options.feature_dim > 0) out.features.resize(num_pixels * options.feature_dim);
  out.visible.assign(n, 0);

  RasterWorkspace local_workspace;
  RasterWorkspace* ws = options.workspace != nullptr ? options.workspace : &local_workspace;
  RunWithThreads(options.num_threads, [&] {
    // 1. Project every Gaussian.
    Stopwatch phase;
    std::vector<ProjectedSplat>& splats = ws->splats;
    splats.resize(n);
    tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 4096), [&](const tbb::blocked_range<size_t>& r) {
      for (size_t i = r.begin(); i < r.end(); ++i) {
        const bool ok = surfel ? ProjectSurfel(cloud, i, params, &splats[i])
                               : ProjectEllipsoid(cloud, i, params, &splats[i]);
        out.visible[i] = ok ? 1 : 0;
      }
    });
    out.stats.preprocess_ms = phase.ElapsedMs();
    phase.Restart();

    // 2. Bin (Gaussian, tile) pairs and sort every tile's list front to back.
    const int num_tiles = params.tiles_x * params.tiles_y;
    BinSplats(splats, out.visible, params, ws);
    const std::vector<uint64_t>& keys = ws->keys;
    const std::vector<uint64_t>& offsets = ws->tile_offsets;
    out.stats.binning_ms = phase.ElapsedMs();
    phase.Restart();

    // 3. Blend every tile.
    std::vector<uint8_t> trace_mask;
    if (options.trace.enabled && !options.trace.pixels.empty()) {
      trace_mask.assign(num_pixels, 0);
      for (uint32_t pix : options.trace.pixels) trace_mask[pix] = 1;
    }
    FrameContext ctx{&options, &params, &splats, &keys, &offsets, &trace_mask, {}};
    const Eigen::Matrix3d world_from_camera = camera.camera_from_world.rotation.transpose();
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 3; ++c) ctx.world_from_camera[3 * r + c] = static_cast<float>(world_from_camera(r, c));
    }
    const bool trace = options.trace.enabled;
    const bool features = options.feature_dim > 0;
    BlendFn blend = surfel ? PickBlend<true>(trace, features) : PickBlend<false>(trace, features);
    std::vector<std::vector<TileTraceEntry>>& tile_traces = ws->tile_traces;
    tile_traces.resize(trace ? num_tiles : 0);
    std::vector<TileCounters> counters(num_tiles);
    tbb::parallel_for(tbb::blocked_range<int>(0, num_tiles, 1), [&](const tbb::blocked_range<int>& r) {
      thread_local TileState state;
      for (int t = r.begin(); t < r.end(); ++t) {
        blend(ctx, t, state, out, counters[t]);
        if (trace) tile_traces[t].swap(state.trace);
      }
    });
    for (const TileCounters& c : counters) {
      out.stats.evaluated_fragments += c.evaluated;
      out.stats.blended_fragments += c.blended;
    }
    out.stats.gaussian_tile_pairs = keys.size();
    if (trace) AssembleTrace(params, tile_traces, options.trace, &out.trace);
    out.stats.blend_ms = phase.ElapsedMs();
  });
  for (uint8_t v : out.visible) out.stats.visible_gaussians += v;
  out.stats.total_ms = total.ElapsedMs();
  return out;
}

}  // namespace instascene
