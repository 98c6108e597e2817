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
#include <cstdlib>
#include <cstring>
#include <memory>
#include <new>
#include <vector>

#if defined(__AVX__) || defined(__FMA__)
#include <immintrin.h>
#endif

#include "common/raster/projection.h"
#include "common/raster/render_types.h"
#include "common/raster/simd8.h"

namespace instascene::raster_internal {

inline constexpr int kTilePixels = kTileSize * kTileSize;

// Growable uninitialised storage for trivially copyable T (malloc/realloc): growing never
// touches the unused part, so slack costs address space, not memory (std::vector::resize would
// write every new element).
template <typename T>
class RawBuffer {
 public:
  T* data() { return data_.get(); }
  const T* data() const { return data_.get(); }
  T& operator[](size_t i) { return data_.get()[i]; }
  const T& operator[](size_t i) const { return data_.get()[i]; }
  size_t capacity() const { return capacity_; }
  void Grow(size_t capacity) {  // keeps the contents
    if (capacity <= capacity_) return;
    void* p = std::realloc(data_.release(), capacity * sizeof(T));
    if (p == nullptr) throw std::bad_alloc();
    data_.reset(static_cast<T*>(p));
    capacity_ = capacity;
  }

 private:
  struct Free {
    void operator()(T* p) const { std::free(p); }
  };
  std::unique_ptr<T, Free> data_;
  size_t capacity_ = 0;
};

// A tile's traced contributions in blending order (front to back within each pixel, pixels
// interleaved), with each entry's local pixel and the count per local pixel. Entries [0, size)
// are valid; the slack lets an 8-lane append store whole vectors and advance by the lanes kept.
// The storage persists in the workspace across frames.
struct TileTrace {
  RawBuffer<Contribution> entries;
  RawBuffer<float> transmittance;  // parallel to entries when TraceOptions::transmittance
  RawBuffer<uint16_t> pixels;      // local pixel of each entry
  size_t size = 0;
  uint32_t counts[kTilePixels + 8];  // + one vector of padding (lanes past the tile add 0)

  // Makes room for `extra` more entries past `size`.
  void Reserve(size_t extra, bool with_transmittance) {
    const size_t need = size + extra;
    if (need > entries.capacity()) {
      const size_t capacity = std::max<size_t>(2 * entries.capacity(), need + 256);
      entries.Grow(capacity);
      pixels.Grow(capacity);
    }
    if (with_transmittance) transmittance.Grow(entries.capacity());
  }
};

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

template <bool kSurfel, TraceMode kTraceMode, bool kFeatures>
void BlendTile(const FrameContext& ctx, int tile, TileState& st, RenderResult& out,
               TileCounters& counters, TileTrace* tile_trace) {
  constexpr bool kTrace = kTraceMode != TraceMode::kNone;
  constexpr bool kVectorTrace = kTraceMode == TraceMode::kVector;
  const ProjectionParams& p = *ctx.params;
  const RenderOptions& opt = *ctx.options;
  const int tx = tile % p.tiles_x, ty = tile / p.tiles_x;
  const int px0 = tx * kTileSize, py0 = ty * kTileSize;
  const int px1 = std::min(px0 + kTileSize, p.width), py1 = std::min(py0 + kTileSize, p.height);
  const int tile_pixels = (px1 - px0) * (py1 - py0);
  const int dim = opt.feature_dim;
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
  if constexpr (kFeatures) st.features.assign(static_cast<size_t>(kTilePixels) * dim, 0.0f);
  if constexpr (kTrace) {
    tile_trace->size = 0;
    std::fill_n(tile_trace->counts, kTilePixels + kLanes, 0u);
  }
  const uint8_t* trace_mask = ctx.trace_mask->empty() ? nullptr : ctx.trace_mask->data();
  const v8f v_min_weight = Splat(opt.trace.min_weight);
  // Every blended weight is at least (1/255) * 1e-4 > 0, so without a positive minimum weight
  // the trace keeps exactly the blended fragments and the per-pixel counts are the contributor
  // counts (copied at the end instead of maintained per vector).
  const bool counts_are_contributors = !(opt.trace.min_weight > 0.0f);
  // The vector append's cursor, kept in registers; tile_trace->size is synced per splat.
  size_t trace_size = 0;
  Contribution* trace_entries = nullptr;
  uint16_t* trace_pixels = nullptr;
  const float near = p.near_plane;
  const bool want_color = opt.color, want_depth = opt.depth, want_normal = opt.normal;
  int num_done = 0;
  v8i tile_blends = {}, tile_live = {};  // lane-wise counters, summed once per tile

  const uint64_t begin = (*ctx.tile_offsets)[tile], end = (*ctx.tile_offsets)[tile + 1];
  for (uint64_t k = begin; k < end && num_done < tile_pixels; ++k) {
    const uint32_t gid = static_cast<uint32_t>((*ctx.keys)[k] & 0xffffffffu);
    const ProjectedSplat& s = (*ctx.splats)[gid];
    // The list visits splats in depth order, i.e. scattered in memory: fetch ahead.
    if (k + kPrefetchDistance < end) {
      const char* ahead = reinterpret_cast<const char*>(
          &(*ctx.splats)[(*ctx.keys)[k + kPrefetchDistance] & 0xffffffffu]);
      __builtin_prefetch(ahead);
      __builtin_prefetch(ahead + 64);
    }
    const int x0 = std::max(px0, s.window[0]), x1 = std::min(px1, s.window[1]);
    const int y0 = std::max(py0, s.window[2]), y1 = std::min(py1, s.window[3]);
    if (x0 >= x1 || y0 >= y1) continue;
    if constexpr (kVectorTrace) {
      // One splat adds at most one entry per window pixel (+ a vector of store slack).
      tile_trace->size = trace_size;
      tile_trace->Reserve(static_cast<size_t>((x1 - x0) * (y1 - y0)) + kLanes, false);
      trace_entries = tile_trace->entries.data();
      trace_pixels = tile_trace->pixels.data();
    }
    const float opacity = s.opacity, cr = s.rgb[0], cg = s.rgb[1], cb = s.rgb[2];
    const float snx = s.normal_view[0], sny = s.normal_view[1], snz = s.normal_view[2];
    const float tw0 = s.tw[0], tw1 = s.tw[1], tw2 = s.tw[2];
    const float mx = s.mean_px[0], my = s.mean_px[1];
    const v8f v_opacity = Splat(opacity), v_cr = Splat(cr), v_cg = Splat(cg), v_cb = Splat(cb);
    const v8f v_nx = Splat(snx), v_ny = Splat(sny), v_nz = Splat(snz);
    const v8f v_tw0 = Splat(tw0), v_tw1 = Splat(tw1), v_tw2 = Splat(tw2);
    const v8f v_tu0 = Splat(s.tu[0]), v_tu1 = Splat(s.tu[1]), v_tu2 = Splat(s.tu[2]);
    const v8f v_mx = Splat(mx), v_depth = Splat(s.depth);
    const uint32_t window_bits = ((1u << (x1 - x0)) - 1u) << (x0 - px0);
    for (int y = y0; y < y1; ++y) {
      // Skip rows whose window pixels are all done (common once most of the tile is opaque).
      if ((st.row_done[y - py0] & window_bits) == window_bits) continue;
      const int row = (y - py0) * kTileSize - px0;  // + x = local pixel index
      // 2DGS: l = y Tw - Tv is constant along the row (stored relative to the origin pixel).
      const float ry = static_cast<float>(y - s.origin_px[1]);
      const v8f l0 = Splat(ry * tw0 + s.tv[0]), l1 = Splat(ry * tw1 + s.tv[1]),
                l2 = Splat(ry * tw2 + s.tv[2]);
      const float dy_s = my - static_cast<float>(y);
      const v8f dy = Splat(dy_s), dy2 = Splat(dy_s * dy_s);
      uint32_t row_blend_bits = 0;
      for (int x = x0; x < x1; x += kLanes) {
        const int i = row + x;
        const v8i xs = SplatI(x) + kLaneIndex;
        const v8i in_range = xs < SplatI(x1);
        const v8f dx = v_mx - __builtin_convertvector(xs, v8f);
        v8f power, depth;
        v8i geometric_ok;
        if constexpr (kSurfel) {
          const v8f rx = __builtin_convertvector(xs - SplatI(s.origin_px[0]), v8f);
          const v8f k0 = rx * v_tw0 + v_tu0, k1 = rx * v_tw1 + v_tu1, k2 = rx * v_tw2 + v_tu2;
          const v8f pz = k0 * l1 - k1 * l0;
          const v8f inv = Splat(1.0f) / pz;
          const v8f u = (k1 * l2 - k2 * l1) * inv;
          const v8f v = (k2 * l0 - k0 * l2) * inv;
          const v8f rho3d = u * u + v * v;
          const v8f rho2d = Splat(2.0f) * (dx * dx + dy2);
          const v8i use3d = rho3d <= rho2d;
          depth = use3d ? u * v_tw0 + v * v_tw1 + v_tw2 : v_tw2;
          power = Splat(-0.5f) * (use3d ? rho3d : rho2d);
          geometric_ok = (pz != Splat(0.0f)) & (depth >= Splat(near)) & (power <= Splat(0.0f));
        } else {
          power = Splat(-0.5f) * (Splat(s.tu[0]) * dx * dx + Splat(s.tu[2]) * dy2) -
                  Splat(s.tu[1]) * dx * dy;
          depth = v_depth;
          geometric_ok = power <= Splat(0.0f);
        }
        const v8f e = v_opacity * FastExpNonPositive8(power);
        const v8f alpha = e < Splat(kAlphaMax) ? e : Splat(kAlphaMax);
        const v8i live = in_range & (LoadI(&st.done[i]) == SplatI(0));
        const v8i valid = live & geometric_ok & (alpha >= Splat(kAlphaMin));
        const v8f T = Load(&st.T[i]);
        const v8f next_T = T * (Splat(1.0f) - alpha);
        const v8i stop = valid & (next_T < Splat(kTransmittanceMin));
        const v8i blend = valid & ~stop;
        const v8f w = blend ? alpha * T : Splat(0.0f);
        // Only the requested outputs are accumulated (the branches are uniform per frame).
        if (want_color) {
          Store(&st.r[i], Load(&st.r[i]) + w * v_cr);
          Store(&st.g[i], Load(&st.g[i]) + w * v_cg);
          Store(&st.b[i], Load(&st.b[i]) + w * v_cb);
        }
        if (want_depth) {
          const v8f d = blend ? depth : Splat(0.0f);
          Store(&st.depth[i], Load(&st.depth[i]) + w * d);
          Store(&st.median[i], (blend & (T > Splat(0.5f))) ? d : Load(&st.median[i]));
        }
        if (want_normal) {
          Store(&st.nx[i], Load(&st.nx[i]) + w * v_nx);
          Store(&st.ny[i], Load(&st.ny[i]) + w * v_ny);
          Store(&st.nz[i], Load(&st.nz[i]) + w * v_nz);
        }
        Store(&st.T[i], blend ? next_T : T);
        StoreI(&st.done[i], LoadI(&st.done[i]) | (stop & SplatI(1)));
        StoreI(&st.contributors[i], LoadI(&st.contributors[i]) + (blend & SplatI(1)));
        if (kFeatures || (kTrace && !kVectorTrace)) {  // inputs of the second pass
          Store(&st.row_weight[x - x0], w);
          Store(&st.row_transmittance[x - x0], T);
        }
        if constexpr (kTrace) {
          if constexpr (kVectorTrace) {
            const v8i keep = blend & (w > v_min_weight);
            const uint32_t keep_bits = MaskBits(keep);
            if (keep_bits != 0) {
              const v8i perm = LoadI(kCompress.perm[keep_bits]);
              v8i w_bits;
              std::memcpy(&w_bits, &w, sizeof(w_bits));
              const v8i wc = Permute(w_bits, perm);
              const v8i g = SplatI(static_cast<int32_t>(gid));
              const v8i lo = __builtin_shufflevector(g, wc, 0, 8, 1, 9, 2, 10, 3, 11);
              const v8i hi = __builtin_shufflevector(g, wc, 4, 12, 5, 13, 6, 14, 7, 15);
              std::memcpy(static_cast<void*>(trace_entries + trace_size), &lo, sizeof(lo));
              std::memcpy(static_cast<void*>(trace_entries + trace_size + 4), &hi, sizeof(hi));
              using v8u16 = uint16_t __attribute__((vector_size(16)));
              const v8u16 local =
                  __builtin_convertvector(Permute(SplatI(i) + kLaneIndex, perm), v8u16);
              std::memcpy(trace_pixels + trace_size, &local, sizeof(local));
              trace_size += static_cast<size_t>(std::popcount(keep_bits));
              if (!counts_are_contributors) {
                int32_t* counts = reinterpret_cast<int32_t*>(&tile_trace->counts[i]);
                StoreI(counts, LoadI(counts) - keep);  // keep lanes are -1
              }
            }
          }
        }
        const uint32_t stop_bits = MaskBits(stop);
        st.row_done[y - py0] |= stop_bits << (x - px0);
        num_done += std::popcount(stop_bits);
        row_blend_bits |= MaskBits(blend) << (x - x0);
        tile_blends -= blend;
        tile_live -= live;
      }
      if (kFeatures || (kTrace && !kVectorTrace)) {
        // Second pass, over the blended pixels of the row only.
        for (uint32_t bits = row_blend_bits; bits != 0; bits &= bits - 1) {
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
            if (!kVectorTrace && w > opt.trace.min_weight &&
                (trace_mask == nullptr || trace_mask[y * p.width + x])) {
              TileTrace& tt = *tile_trace;
              tt.Reserve(1, opt.trace.transmittance);
              tt.entries[tt.size] = Contribution{gid, w};
              if (opt.trace.transmittance)
                tt.transmittance[tt.size] = st.row_transmittance[dx_lane];
              tt.pixels[tt.size] = static_cast<uint16_t>(i);
              ++tt.size;
              ++tt.counts[i];
            }
          }
        }
      }
    }
  }
  if constexpr (kVectorTrace) {
    tile_trace->size = trace_size;
    if (counts_are_contributors) {
      for (int l = 0; l < kTilePixels; ++l)
        tile_trace->counts[l] = static_cast<uint32_t>(st.contributors[l]);
    }
  }
  counters.evaluated += static_cast<uint64_t>(SumLanes(tile_live));
  counters.blended += static_cast<uint64_t>(SumLanes(tile_blends));

  // Write the tile into the frame buffers.
  const float* R = ctx.world_from_camera;
  for (int y = py0; y < py1; ++y) {
    for (int x = px0; x < px1; ++x) {
      const int i = (y - py0) * kTileSize + (x - px0);
      const size_t pix = static_cast<size_t>(y) * p.width + x;
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

}  // namespace instascene::raster_internal
