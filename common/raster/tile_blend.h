// common/raster/tile_blend.h: the per-tile compositing kernel (internal to the rasterizer).
//
// One call blends one 16x16 tile front to back. For each splat of the tile's depth-sorted list and
// each row of its pixel window, the pixels are processed in one branch-free loop (planar per-pixel
// state, selects instead of branches) that the compiler vectorises across pixels; feature
// accumulation and tracing, which append or loop over channels, run in a second scalar pass over
// the row using the weights the first pass stored. Semantics are exactly ALGORITHM.md 2.4.
// Thread-safety: each call touches only its tile's pixels and its own TileState.
#pragma once

#include <algorithm>
#include <bit>
#include <cstdint>
#include <cstring>
#include <vector>

#if defined(__AVX__) || defined(__FMA__)
#include <immintrin.h>
#endif

#include "common/raster/projection.h"
#include "common/raster/render_types.h"
#include "common/raster/simd8.h"
#include "common/raster/tile_trace.h"

namespace instascene::raster_internal {

// Everything a tile task reads.
struct FrameContext {
  const RenderOptions* options;
  const ProjectionParams* params;
  const std::vector<ProjectedSplat>* splats;
  const std::vector<uint64_t>* keys;          // per tile, sorted: (depth bits << 32) | gaussian
  const std::vector<uint64_t>* tile_offsets;  // num_tiles + 1
  const std::vector<uint8_t>* trace_mask;     // per pixel, when tracing a subset
  float world_from_camera[9];                 // row-major rotation
};

struct TileCounters {
  uint64_t evaluated = 0, blended = 0;
};

inline constexpr uint64_t kPrefetchDistance = 8;  // splats fetched ahead in a tile's list

// Per-thread scratch for one tile, planar so the pixel loop vectorises. Arrays have kLanes of
// padding: a vector that starts in a row's last pixels reads (and writes back unchanged) the
// following entries.
struct alignas(64) TileState {
  static constexpr int kPadded = kTilePixels + kLanes;
  float T[kPadded], r[kPadded], g[kPadded], b[kPadded];
  float depth[kPadded], median[kPadded];
  float nx[kPadded], ny[kPadded], nz[kPadded];
  int32_t done[kPadded];
  int32_t contributors[kPadded];
  uint32_t row_done[kTileSize];  // bit x of row y: pixel (x, y) of the tile is done
  float row_weight[kTileSize + kLanes], row_transmittance[kTileSize + kLanes];
  std::vector<float> features;
};

// Blends one tile; with tracing, `tile_trace` receives the tile's contributions.
// How a tile records its contributions: not at all, 8 lanes at a time in the first pass (full
// traces without transmittance: the common, large case), or per pixel in the second pass (pixel
// subsets, transmittance). A template parameter, so each kernel carries only its own code and
// live values (the full-trace blend took ~10 ms more per 1280x720 frame while it also held the
// scalar path).
enum class TraceMode { kNone, kVector, kScalar };

#define INSTASCENE_INLINE inline __attribute__((always_inline))

// Clears the tile's accumulators (and its trace) before its first splat.
template <bool kTrace, bool kFeatures>
void ResetTile(const RenderOptions& opt, TileState& st, TileTrace* tile_trace) {
  std::fill_n(st.T, TileState::kPadded, 1.0f);
  if (opt.color) {
    for (float* a : {st.r, st.g, st.b}) std::fill_n(a, TileState::kPadded, 0.0f);
  }
  if (opt.depth) {
    for (float* a : {st.depth, st.median}) std::fill_n(a, TileState::kPadded, 0.0f);
  }
  if (opt.normal) {
    for (float* a : {st.nx, st.ny, st.nz}) std::fill_n(a, TileState::kPadded, 0.0f);
  }
  std::fill_n(st.done, TileState::kPadded, 0);
  std::fill_n(st.row_done, kTileSize, 0u);
  std::fill_n(st.contributors, TileState::kPadded, 0);
  if constexpr (kFeatures)
    st.features.assign(static_cast<size_t>(kTilePixels) * opt.feature_dim, 0.0f);
  if constexpr (kTrace) {
    tile_trace->size = 0;
    std::fill_n(tile_trace->counts, kTilePixels + kLanes, 0u);
  }
}

// One splat's values broadcast to the 8 lanes, once per splat.
struct SplatLanes {
  v8f opacity, cr, cg, cb, nx, ny, nz, tw0, tw1, tw2, tu0, tu1, tu2, mx, depth;
  INSTASCENE_INLINE explicit SplatLanes(const ProjectedSplat& s)
      : opacity(Splat(s.opacity)),
        cr(Splat(s.rgb[0])),
        cg(Splat(s.rgb[1])),
        cb(Splat(s.rgb[2])),
        nx(Splat(s.normal_view[0])),
        ny(Splat(s.normal_view[1])),
        nz(Splat(s.normal_view[2])),
        tw0(Splat(s.tw[0])),
        tw1(Splat(s.tw[1])),
        tw2(Splat(s.tw[2])),
        tu0(Splat(s.tu[0])),
        tu1(Splat(s.tu[1])),
        tu2(Splat(s.tu[2])),
        mx(Splat(s.mean_px[0])),
        depth(Splat(s.depth)) {}
};

// What a splat row's pixels share: for 2DGS, l = y Tw - Tv (constant along the row, relative to
// the origin pixel), and the offsets from the splat's centre in y.
struct RowLanes {
  v8f l0, l1, l2, dy, dy2;
};

// The splat's Gaussian exponent and depth at 8 pixels of a row, and whether the geometry admits
// them: 2DGS's ray-splat intersection with the 2D low-pass fallback, or 3DGS's conic.
struct Footprint {
  v8f power, depth;
  v8i ok;
};
template <bool kSurfel>
INSTASCENE_INLINE Footprint EvaluateFootprint(const ProjectedSplat& s, const SplatLanes& v,
                                              const RowLanes& row, v8i xs, v8f dx, float near) {
  Footprint f;
  if constexpr (kSurfel) {
    const v8f rx = __builtin_convertvector(xs - SplatI(s.origin_px[0]), v8f);
    const v8f k0 = rx * v.tw0 + v.tu0, k1 = rx * v.tw1 + v.tu1, k2 = rx * v.tw2 + v.tu2;
    const v8f pz = k0 * row.l1 - k1 * row.l0;
    const v8f inv = Splat(1.0f) / pz;
    const v8f u = (k1 * row.l2 - k2 * row.l1) * inv;
    const v8f w = (k2 * row.l0 - k0 * row.l2) * inv;
    const v8f rho3d = u * u + w * w;
    const v8f rho2d = Splat(2.0f) * (dx * dx + row.dy2);
    const v8i use3d = rho3d <= rho2d;
    f.depth = use3d ? u * v.tw0 + w * v.tw1 + v.tw2 : v.tw2;
    f.power = Splat(-0.5f) * (use3d ? rho3d : rho2d);
    f.ok = (pz != Splat(0.0f)) & (f.depth >= Splat(near)) & (f.power <= Splat(0.0f));
  } else {
    f.power = Splat(-0.5f) * (Splat(s.tu[0]) * dx * dx + Splat(s.tu[2]) * row.dy2) -
              Splat(s.tu[1]) * dx * row.dy;
    f.depth = v.depth;
    f.ok = f.power <= Splat(0.0f);
  }
  return f;
}

// The outputs a frame requests (copied out of the options: the branches are uniform per frame).
struct Outputs {
  bool color, depth, normal;
};

// Adds the weights `w` of the pixels i..i+7 to the requested outputs; the median depth is the
// depth where T crosses 0.5.
INSTASCENE_INLINE void Accumulate(Outputs want, const SplatLanes& v, TileState& st, int i, v8f w,
                                  v8i blend, v8f T, v8f depth) {
  if (want.color) {
    Store(&st.r[i], Load(&st.r[i]) + w * v.cr);
    Store(&st.g[i], Load(&st.g[i]) + w * v.cg);
    Store(&st.b[i], Load(&st.b[i]) + w * v.cb);
  }
  if (want.depth) {
    const v8f d = blend ? depth : Splat(0.0f);
    Store(&st.depth[i], Load(&st.depth[i]) + w * d);
    Store(&st.median[i], (blend & (T > Splat(0.5f))) ? d : Load(&st.median[i]));
  }
  if (want.normal) {
    Store(&st.nx[i], Load(&st.nx[i]) + w * v.nx);
    Store(&st.ny[i], Load(&st.ny[i]) + w * v.ny);
    Store(&st.nz[i], Load(&st.nz[i]) + w * v.nz);
  }
}

// The vector trace's append cursor, kept in registers; tile_trace->size is synced per splat.
struct VectorTraceCursor {
  size_t size = 0;
  Contribution* entries = nullptr;
  uint16_t* pixels = nullptr;
};

// Appends the lanes of pixels i..i+7 that blend with a weight above the minimum: (gid, w) pairs
// and local pixels compacted by a permutation; counts kept per pixel unless they equal the
// contributor counts.
INSTASCENE_INLINE void AppendVectorTrace(uint32_t gid, int i, v8f w, v8i blend, v8f min_weight,
                                         bool counts_are_contributors, TileTrace* tile_trace,
                                         VectorTraceCursor& cursor) {
  const v8i keep = blend & (w > min_weight);
  const uint32_t keep_bits = MaskBits(keep);
  if (keep_bits == 0) return;
  const v8i perm = LoadI(kCompress.perm[keep_bits]);
  v8i w_bits;
  std::memcpy(&w_bits, &w, sizeof(w_bits));
  const v8i wc = Permute(w_bits, perm);
  const v8i g = SplatI(static_cast<int32_t>(gid));
  const v8i lo = __builtin_shufflevector(g, wc, 0, 8, 1, 9, 2, 10, 3, 11);
  const v8i hi = __builtin_shufflevector(g, wc, 4, 12, 5, 13, 6, 14, 7, 15);
  std::memcpy(static_cast<void*>(cursor.entries + cursor.size), &lo, sizeof(lo));
  std::memcpy(static_cast<void*>(cursor.entries + cursor.size + 4), &hi, sizeof(hi));
  using v8u16 = uint16_t __attribute__((vector_size(16)));
  const v8u16 local = __builtin_convertvector(Permute(SplatI(i) + kLaneIndex, perm), v8u16);
  std::memcpy(cursor.pixels + cursor.size, &local, sizeof(local));
  cursor.size += static_cast<size_t>(std::popcount(keep_bits));
  if (!counts_are_contributors) {
    int32_t* counts = reinterpret_cast<int32_t*>(&tile_trace->counts[i]);
    StoreI(counts, LoadI(counts) - keep);  // keep lanes are -1
  }
}

// The second pass over a row's blended pixels (`blend_bits`, from x0): features accumulated per
// channel, and the scalar trace (pixel subsets, transmittance).
template <bool kTrace, bool kFeatures>
INSTASCENE_INLINE void RowSecondPass(const FrameContext& ctx, uint32_t gid, int row, int x0, int y,
                                     uint32_t blend_bits, const uint8_t* trace_mask, TileState& st,
                                     TileTrace* tile_trace) {
  const RenderOptions& opt = *ctx.options;
  const int dim = opt.feature_dim;
  for (uint32_t bits = blend_bits; bits != 0; bits &= bits - 1) {
    const int dx_lane = std::countr_zero(bits);
    const int x = x0 + dx_lane;
    const float w = st.row_weight[dx_lane];
    const int i = row + x;
    if constexpr (kFeatures) {
      const float* f = opt.features + static_cast<size_t>(gid) * dim;
      float* e = &st.features[static_cast<size_t>(i) * dim];
      for (int c = 0; c < dim; ++c) e[c] += w * f[c];
    }
    if constexpr (kTrace) {
      if (w > opt.trace.min_weight &&
          (trace_mask == nullptr || trace_mask[y * ctx.params->width + x])) {
        TileTrace& tt = *tile_trace;
        tt.Reserve(1, opt.trace.transmittance);
        tt.entries[tt.size] = Contribution{gid, w};
        if (opt.trace.transmittance) tt.transmittance[tt.size] = st.row_transmittance[dx_lane];
        tt.pixels[tt.size] = static_cast<uint16_t>(i);
        ++tt.size;
        ++tt.counts[i];
      }
    }
  }
}

// Writes the tile's pixels [px0, px1) x [py0, py1) into the frame buffers.
template <bool kFeatures>
void WriteTile(const FrameContext& ctx, const TileState& st, int px0, int py0, int px1, int py1,
               RenderResult& out) {
  const RenderOptions& opt = *ctx.options;
  const int width = ctx.params->width, dim = opt.feature_dim;
  const float* R = ctx.world_from_camera;
  for (int y = py0; y < py1; ++y) {
    for (int x = px0; x < px1; ++x) {
      const int i = (y - py0) * kTileSize + (x - px0);
      const size_t pix = static_cast<size_t>(y) * width + x;
      const float T = st.T[i];
      const float a = 1.0f - T;
      out.alpha[pix] = a;
      out.num_contributors[pix] = static_cast<uint32_t>(st.contributors[i]);
      if (opt.color) {
        out.color[3 * pix] = st.r[i] + T * opt.background[0];
        out.color[3 * pix + 1] = st.g[i] + T * opt.background[1];
        out.color[3 * pix + 2] = st.b[i] + T * opt.background[2];
      }
      if (opt.depth) {
        const float dval = st.depth[i] / a;
        out.depth[pix] = std::isfinite(dval) ? dval : 0.0f;
        out.median_depth[pix] = st.median[i];
      }
      if (opt.normal) {
        for (int c = 0; c < 3; ++c) {
          out.normal[3 * pix + c] =
              R[3 * c] * st.nx[i] + R[3 * c + 1] * st.ny[i] + R[3 * c + 2] * st.nz[i];
        }
      }
      if constexpr (kFeatures) {
        std::memcpy(&out.features[pix * dim], &st.features[static_cast<size_t>(i) * dim],
                    sizeof(float) * dim);
      }
    }
  }
}

// A tile's bounds and what its splats' rows share while they blend.
struct TileRun {
  int px0, py0, px1, py1;
  int tile_pixels;
  Outputs want;
  const uint8_t* trace_mask;  // null: every pixel traced
  v8f min_weight;             // the trace's, in lanes
  // Every blended weight is at least (1/255) * 1e-4 > 0, so without a positive minimum weight
  // the trace keeps exactly the blended fragments and the per-pixel counts are the contributor
  // counts (copied at the end instead of maintained per vector).
  bool counts_are_contributors;
  VectorTraceCursor cursor;
  int num_done = 0;
  v8i blends = {}, live = {};  // lane-wise counters, summed once per tile
};

// Tile `tile`'s bounds and the frame's options its rows read.
INSTASCENE_INLINE TileRun StartTile(const FrameContext& ctx, int tile) {
  const ProjectionParams& p = *ctx.params;
  const RenderOptions& opt = *ctx.options;
  const int tx = tile % p.tiles_x, ty = tile / p.tiles_x;
  TileRun run{.px0 = tx * kTileSize, .py0 = ty * kTileSize};
  run.px1 = std::min(run.px0 + kTileSize, p.width);
  run.py1 = std::min(run.py0 + kTileSize, p.height);
  run.tile_pixels = (run.px1 - run.px0) * (run.py1 - run.py0);
  run.want = Outputs{opt.color, opt.depth, opt.normal};
  run.trace_mask = ctx.trace_mask->empty() ? nullptr : ctx.trace_mask->data();
  run.min_weight = Splat(opt.trace.min_weight);
  run.counts_are_contributors = !(opt.trace.min_weight > 0.0f);
  return run;
}

// Blends splat `s` (Gaussian `gid`) into row y of the tile, pixels [x0, x1): the branch-free
// vector pass, then the second pass where features or the scalar trace need it.
template <bool kSurfel, TraceMode kTraceMode, bool kFeatures>
INSTASCENE_INLINE void BlendSplatRow(const FrameContext& ctx, const ProjectedSplat& s,
                                     const SplatLanes& v, uint32_t gid, int y, int x0, int x1,
                                     TileRun& run, TileState& st, TileTrace* tile_trace) {
  constexpr bool kTrace = kTraceMode != TraceMode::kNone;
  constexpr bool kVectorTrace = kTraceMode == TraceMode::kVector;
  constexpr bool kSecondPass = kFeatures || (kTrace && !kVectorTrace);
  const int row = (y - run.py0) * kTileSize - run.px0;  // + x = local pixel index
  const float ry = static_cast<float>(y - s.origin_px[1]);
  const float dy_s = s.mean_px[1] - static_cast<float>(y);
  const RowLanes row_lanes{Splat(ry * s.tw[0] + s.tv[0]), Splat(ry * s.tw[1] + s.tv[1]),
                           Splat(ry * s.tw[2] + s.tv[2]), Splat(dy_s), Splat(dy_s * dy_s)};
  uint32_t row_blend_bits = 0;
  for (int x = x0; x < x1; x += kLanes) {
    const int i = row + x;
    const v8i xs = SplatI(x) + kLaneIndex;
    const v8i in_range = xs < SplatI(x1);
    const v8f dx = v.mx - __builtin_convertvector(xs, v8f);
    const Footprint f = EvaluateFootprint<kSurfel>(s, v, row_lanes, xs, dx, ctx.params->near_plane);
    const v8f e = v.opacity * FastExpNonPositive8(f.power);
    const v8f alpha = e < Splat(kAlphaMax) ? e : Splat(kAlphaMax);
    const v8i live = in_range & (LoadI(&st.done[i]) == SplatI(0));
    const v8i valid = live & f.ok & (alpha >= Splat(kAlphaMin));
    const v8f T = Load(&st.T[i]);
    const v8f next_T = T * (Splat(1.0f) - alpha);
    const v8i stop = valid & (next_T < Splat(kTransmittanceMin));
    const v8i blend = valid & ~stop;
    const v8f w = blend ? alpha * T : Splat(0.0f);
    Accumulate(run.want, v, st, i, w, blend, T, f.depth);
    Store(&st.T[i], blend ? next_T : T);
    StoreI(&st.done[i], LoadI(&st.done[i]) | (stop & SplatI(1)));
    StoreI(&st.contributors[i], LoadI(&st.contributors[i]) + (blend & SplatI(1)));
    if constexpr (kSecondPass) {  // inputs of the second pass
      Store(&st.row_weight[x - x0], w);
      Store(&st.row_transmittance[x - x0], T);
    }
    if constexpr (kVectorTrace) {
      AppendVectorTrace(gid, i, w, blend, run.min_weight, run.counts_are_contributors, tile_trace,
                        run.cursor);
    }
    const uint32_t stop_bits = MaskBits(stop);
    st.row_done[y - run.py0] |= stop_bits << (x - run.px0);
    run.num_done += std::popcount(stop_bits);
    row_blend_bits |= MaskBits(blend) << (x - x0);
    run.blends -= blend;
    run.live -= live;
  }
  if constexpr (kSecondPass) {
    RowSecondPass<kTrace && !kVectorTrace, kFeatures>(ctx, gid, row, x0, y, row_blend_bits,
                                                      run.trace_mask, st, tile_trace);
  }
}

template <bool kSurfel, TraceMode kTraceMode, bool kFeatures>
void BlendTile(const FrameContext& ctx, int tile, TileState& st, RenderResult& out,
               TileCounters& counters, TileTrace* tile_trace) {
  constexpr bool kTrace = kTraceMode != TraceMode::kNone;
  constexpr bool kVectorTrace = kTraceMode == TraceMode::kVector;
  const RenderOptions& opt = *ctx.options;
  TileRun run = StartTile(ctx, tile);
  ResetTile<kTrace, kFeatures>(opt, st, tile_trace);

  const uint64_t begin = (*ctx.tile_offsets)[tile], end = (*ctx.tile_offsets)[tile + 1];
  for (uint64_t k = begin; k < end && run.num_done < run.tile_pixels; ++k) {
    const uint32_t gid = static_cast<uint32_t>((*ctx.keys)[k] & 0xffffffffu);
    const ProjectedSplat& s = (*ctx.splats)[gid];
    // The list visits splats in depth order, i.e. scattered in memory: fetch ahead.
    if (k + kPrefetchDistance < end) {
      const char* ahead = reinterpret_cast<const char*>(
          &(*ctx.splats)[(*ctx.keys)[k + kPrefetchDistance] & 0xffffffffu]);
      __builtin_prefetch(ahead);
      __builtin_prefetch(ahead + 64);
    }
    const int x0 = std::max(run.px0, s.window[0]), x1 = std::min(run.px1, s.window[1]);
    const int y0 = std::max(run.py0, s.window[2]), y1 = std::min(run.py1, s.window[3]);
    if (x0 >= x1 || y0 >= y1) continue;
    if constexpr (kVectorTrace) {
      // One splat adds at most one entry per window pixel (+ a vector of store slack).
      tile_trace->size = run.cursor.size;
      tile_trace->Reserve(static_cast<size_t>((x1 - x0) * (y1 - y0)) + kLanes, false);
      run.cursor.entries = tile_trace->entries.data();
      run.cursor.pixels = tile_trace->pixels.data();
    }
    const SplatLanes v(s);
    const uint32_t window_bits = ((1u << (x1 - x0)) - 1u) << (x0 - run.px0);
    for (int y = y0; y < y1; ++y) {
      // Skip rows whose window pixels are all done (common once most of the tile is opaque).
      if ((st.row_done[y - run.py0] & window_bits) == window_bits) continue;
      BlendSplatRow<kSurfel, kTraceMode, kFeatures>(ctx, s, v, gid, y, x0, x1, run, st, tile_trace);
    }
  }
  if constexpr (kVectorTrace) {
    tile_trace->size = run.cursor.size;
    if (run.counts_are_contributors) {
      for (int l = 0; l < kTilePixels; ++l)
        tile_trace->counts[l] = static_cast<uint32_t>(st.contributors[l]);
    }
  }
  counters.evaluated += static_cast<uint64_t>(SumLanes(run.live));
  counters.blended += static_cast<uint64_t>(SumLanes(run.blends));
  WriteTile<kFeatures>(ctx, st, run.px0, run.py0, run.px1, run.py1, out);
}

#undef INSTASCENE_INLINE

}  // namespace instascene::raster_internal
