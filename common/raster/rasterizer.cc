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

namespace instascene {
namespace {

constexpr int kTilePixels = kTileSize * kTileSize;

// One traced contribution inside a tile, before grouping by pixel.
struct TileTraceEntry {
  uint16_t local_pixel;
  Contribution contribution;
};

// Everything a tile task reads.
struct FrameContext {
  const GaussianCloud* cloud;
  const RenderOptions* options;
  const ProjectionParams* params;
  const std::vector<ProjectedSplat>* splats;
  const std::vector<uint64_t>* keys;         // per tile, sorted: (depth bits << 32) | gaussian
  const std::vector<uint64_t>* tile_offsets; // num_tiles + 1
  const std::vector<uint8_t>* trace_mask;    // per pixel, when tracing a subset
  bool surfel;
  float camera_from_world_t[9];              // rotation transposed: world_from_camera
};

struct TileCounters {
  uint64_t evaluated = 0, blended = 0;
};

// Per-thread scratch for one tile.
struct TileState {
  float T[kTilePixels];
  float color[kTilePixels * 3];
  float depth[kTilePixels];
  float median[kTilePixels];
  float normal[kTilePixels * 3];
  uint32_t contributors[kTilePixels];
  uint8_t done[kTilePixels];
  std::vector<float> features;
  std::vector<TileTraceEntry> trace;
};

template <bool kSurfel, bool kTrace, bool kFeatures>
void BlendTile(const FrameContext& ctx, int tile, TileState& st, RenderResult& out,
               std::vector<TileTraceEntry>* tile_trace, TileCounters& counters) {
  const ProjectionParams& p = *ctx.params;
  const RenderOptions& opt = *ctx.options;
  const int tx = tile % p.tiles_x, ty = tile / p.tiles_x;
  const int px0 = tx * kTileSize, py0 = ty * kTileSize;
  const int px1 = std::min(px0 + kTileSize, p.width), py1 = std::min(py0 + kTileSize, p.height);
  const int tile_pixels = (px1 - px0) * (py1 - py0);
  const int dim = opt.feature_dim;
  std::fill_n(st.T, kTilePixels, 1.0f);
  std::fill_n(st.color, kTilePixels * 3, 0.0f);
  std::fill_n(st.depth, kTilePixels, 0.0f);
  std::fill_n(st.median, kTilePixels, 0.0f);
  std::fill_n(st.normal, kTilePixels * 3, 0.0f);
  std::fill_n(st.contributors, kTilePixels, 0u);
  std::fill_n(st.done, kTilePixels, uint8_t{0});
  if constexpr (kFeatures) st.features.assign(static_cast<size_t>(kTilePixels) * dim, 0.0f);
  if constexpr (kTrace) st.trace.clear();
  const uint8_t* trace_mask = ctx.trace_mask->empty() ? nullptr : ctx.trace_mask->data();
  const float near = p.near_plane;
  int num_done = 0;
  uint64_t evaluated = 0, blended = 0;

  const uint64_t begin = (*ctx.tile_offsets)[tile], end = (*ctx.tile_offsets)[tile + 1];
  for (uint64_t k = begin; k < end && num_done < tile_pixels; ++k) {
    const uint32_t g = static_cast<uint32_t>((*ctx.keys)[k] & 0xffffffffu);
    const ProjectedSplat& s = (*ctx.splats)[g];
    const int x0 = std::max(px0, s.window[0]), x1 = std::min(px1, s.window[1]);
    const int y0 = std::max(py0, s.window[2]), y1 = std::min(py1, s.window[3]);
    if (x0 >= x1 || y0 >= y1) continue;
    const float* f = kFeatures ? opt.features + static_cast<size_t>(g) * dim : nullptr;
    for (int y = y0; y < y1; ++y) {
      const float fy = static_cast<float>(y);
      // 2DGS: l = y Tw - Tv is constant along the row (stored relative to the origin pixel).
      const float ry = static_cast<float>(y - s.origin_px[1]);
      const float l0 = ry * s.tw[0] + s.tv[0], l1 = ry * s.tw[1] + s.tv[1], l2 = ry * s.tw[2] + s.tv[2];
      const float dy = s.mean_px[1] - fy;
      for (int x = x0; x < x1; ++x) {
        const int local = (y - py0) * kTileSize + (x - px0);
        if (st.done[local]) continue;
        ++evaluated;
        const float fx = static_cast<float>(x);
        const float dx = s.mean_px[0] - fx;
        float power, depth;
        if constexpr (kSurfel) {
          const float rx = static_cast<float>(x - s.origin_px[0]);
          const float k0 = rx * s.tw[0] + s.tu[0], k1 = rx * s.tw[1] + s.tu[1], k2 = rx * s.tw[2] + s.tu[2];
          const float pz = k0 * l1 - k1 * l0;
          if (pz == 0.0f) continue;
          const float u = (k1 * l2 - k2 * l1) / pz;
          const float v = (k2 * l0 - k0 * l2) / pz;
          const float rho3d = u * u + v * v;
          const float rho2d = 2.0f * (dx * dx + dy * dy);
          const bool use3d = rho3d <= rho2d;
          depth = use3d ? u * s.tw[0] + v * s.tw[1] + s.tw[2] : s.tw[2];
          if (depth < near) continue;
          power = -0.5f * (use3d ? rho3d : rho2d);
        } else {
          power = -0.5f * (s.tu[0] * dx * dx + s.tu[2] * dy * dy) - s.tu[1] * dx * dy;
          depth = s.depth;
        }
        if (power > 0.0f) continue;
        const float alpha = std::min(kAlphaMax, s.opacity * std::exp(power));
        if (alpha < kAlphaMin) continue;
        const float T = st.T[local];
        const float next_T = T * (1.0f - alpha);
        if (next_T < kTransmittanceMin) {
          st.done[local] = 1;
          ++num_done;
          continue;
        }
        const float w = alpha * T;
        ++blended;
        st.color[3 * local] += w * s.rgb[0];
        st.color[3 * local + 1] += w * s.rgb[1];
        st.color[3 * local + 2] += w * s.rgb[2];
        st.depth[local] += w * depth;
        st.normal[3 * local] += w * s.normal_view[0];
        st.normal[3 * local + 1] += w * s.normal_view[1];
        st.normal[3 * local + 2] += w * s.normal_view[2];
        if (T > 0.5f) st.median[local] = depth;
        st.T[local] = next_T;
        ++st.contributors[local];
        if constexpr (kFeatures) {
          float* e = &st.features[static_cast<size_t>(local) * dim];
          for (int d = 0; d < dim; ++d) e[d] += w * f[d];
        }
        if constexpr (kTrace) {
          if (w > opt.trace.min_weight && (trace_mask == nullptr || trace_mask[y * p.width + x])) {
            st.trace.push_back({static_cast<uint16_t>(local), {g, w, T}});
          }
        }
      }
    }
  }
  counters.evaluated += evaluated;
  counters.blended += blended;

  // Write the tile into the frame buffers.
  const float* R = ctx.camera_from_world_t;
  for (int y = py0; y < py1; ++y) {
    for (int x = px0; x < px1; ++x) {
      const int local = (y - py0) * kTileSize + (x - px0);
      const size_t pix = static_cast<size_t>(y) * p.width + x;
      const float T = st.T[local];
      const float a = 1.0f - T;
      out.alpha[pix] = a;
      out.num_contributors[pix] = st.contributors[local];
      if (opt.color) {
        for (int c = 0; c < 3; ++c) out.color[3 * pix + c] = st.color[3 * local + c] + T * opt.background[c];
      }
      if (opt.depth) {
        const float dval = st.depth[local] / a;
        out.depth[pix] = std::isfinite(dval) ? dval : 0.0f;
        out.median_depth[pix] = st.median[local];
      }
      if (opt.normal) {
        const float* n = &st.normal[3 * local];
        for (int r = 0; r < 3; ++r) out.normal[3 * pix + r] = R[3 * r] * n[0] + R[3 * r + 1] * n[1] + R[3 * r + 2] * n[2];
      }
      if constexpr (kFeatures) {
        std::memcpy(&out.features[pix * dim], &st.features[static_cast<size_t>(local) * dim], sizeof(float) * dim);
      }
    }
  }
  if constexpr (kTrace) {
    // Group by pixel, keeping front-to-back order within each pixel (stable).
    std::stable_sort(st.trace.begin(), st.trace.end(),
                     [](const TileTraceEntry& a, const TileTraceEntry& b) { return a.local_pixel < b.local_pixel; });
    *tile_trace = st.trace;
  }
}

using BlendFn = void (*)(const FrameContext&, int, TileState&, RenderResult&,
                         std::vector<TileTraceEntry>*, TileCounters&);

template <bool kSurfel>
BlendFn PickBlend(bool trace, bool features) {
  if (trace) return features ? BlendTile<kSurfel, true, true> : BlendTile<kSurfel, true, false>;
  return features ? BlendTile<kSurfel, false, true> : BlendTile<kSurfel, false, false>;
}

// Builds the CSR trace from per-tile lists (each grouped by local pixel, front to back).
void AssembleTrace(const ProjectionParams& p, const std::vector<std::vector<TileTraceEntry>>& tiles,
                   const TraceOptions& trace_options, ContributorTrace* trace) {
  const size_t num_pixels = static_cast<size_t>(p.width) * p.height;
  if (trace_options.pixels.empty()) {
    trace->pixels.resize(num_pixels);
    for (size_t i = 0; i < num_pixels; ++i) trace->pixels[i] = static_cast<uint32_t>(i);
  } else {
    trace->pixels = trace_options.pixels;
  }
  // slot[pixel] = row of that pixel in the CSR, or -1.
  std::vector<int64_t> slot(num_pixels, -1);
  for (size_t i = 0; i < trace->pixels.size(); ++i) slot[trace->pixels[i]] = static_cast<int64_t>(i);
  std::vector<uint64_t> counts(trace->pixels.size() + 1, 0);
  auto pixel_of = [&](int tile, uint16_t local) {
    const int tx = tile % p.tiles_x, ty = tile / p.tiles_x;
    return static_cast<size_t>(ty * kTileSize + local / kTileSize) * p.width + tx * kTileSize + local % kTileSize;
  };
  for (size_t t = 0; t < tiles.size(); ++t) {
    for (const TileTraceEntry& e : tiles[t]) ++counts[slot[pixel_of(static_cast<int>(t), e.local_pixel)] + 1];
  }
  for (size_t i = 1; i < counts.size(); ++i) counts[i] += counts[i - 1];
  trace->offsets = counts;
  trace->entries.resize(counts.back());
  tbb::parallel_for(size_t{0}, tiles.size(), [&](size_t t) {
    size_t i = 0;
    const auto& list = tiles[t];
    while (i < list.size()) {
      const uint16_t local = list[i].local_pixel;
      uint64_t dst = trace->offsets[slot[pixel_of(static_cast<int>(t), local)]];
      for (; i < list.size() && list[i].local_pixel == local; ++i) trace->entries[dst++] = list[i].contribution;
    }
  });
}

}  // namespace

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

  RunWithThreads(options.num_threads, [&] {
    // 1. Project every Gaussian.
    Stopwatch phase;
    std::vector<ProjectedSplat> splats(n);
    tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 4096), [&](const tbb::blocked_range<size_t>& r) {
      for (size_t i = r.begin(); i < r.end(); ++i) {
        const bool ok = surfel ? ProjectSurfel(cloud, i, params, &splats[i])
                               : ProjectEllipsoid(cloud, i, params, &splats[i]);
        out.visible[i] = ok ? 1 : 0;
      }
    });
    out.stats.preprocess_ms = phase.ElapsedMs();
    phase.Restart();

    // 2. Bin (Gaussian, tile) pairs; keys sort by centre depth, ties by Gaussian index (as the
    //    stable CUDA radix sort over Gaussian-ordered input).
    const int num_tiles = params.tiles_x * params.tiles_y;
    std::vector<uint64_t> offsets(num_tiles + 1, 0);
    for (size_t i = 0; i < n; ++i) {
      if (!out.visible[i]) continue;
      const int32_t* t = splats[i].tiles;
      for (int ty = t[2]; ty < t[3]; ++ty) {
        for (int tx = t[0]; tx < t[1]; ++tx) ++offsets[ty * params.tiles_x + tx + 1];
      }
    }
    for (int t = 0; t < num_tiles; ++t) offsets[t + 1] += offsets[t];
    std::vector<uint64_t> keys(offsets.back());
    {
      std::vector<uint64_t> cursor(offsets.begin(), offsets.end() - 1);
      for (size_t i = 0; i < n; ++i) {
        if (!out.visible[i]) continue;
        const uint64_t key = (uint64_t{std::bit_cast<uint32_t>(splats[i].depth)} << 32) | i;
        const int32_t* t = splats[i].tiles;
        for (int ty = t[2]; ty < t[3]; ++ty) {
          for (int tx = t[0]; tx < t[1]; ++tx) keys[cursor[ty * params.tiles_x + tx]++] = key;
        }
      }
    }
    tbb::parallel_for(0, num_tiles, [&](int t) { std::sort(keys.begin() + offsets[t], keys.begin() + offsets[t + 1]); });
    out.stats.binning_ms = phase.ElapsedMs();
    phase.Restart();

    // 3. Blend every tile.
    std::vector<uint8_t> trace_mask;
    if (options.trace.enabled && !options.trace.pixels.empty()) {
      trace_mask.assign(num_pixels, 0);
      for (uint32_t pix : options.trace.pixels) trace_mask[pix] = 1;
    }
    FrameContext ctx{&cloud, &options, &params, &splats, &keys, &offsets, &trace_mask, surfel, {}};
    const Eigen::Matrix3d world_from_camera = camera.camera_from_world.rotation.transpose();
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 3; ++c) ctx.camera_from_world_t[3 * r + c] = static_cast<float>(world_from_camera(r, c));
    }
    const bool trace = options.trace.enabled;
    const bool features = options.feature_dim > 0;
    BlendFn blend = surfel ? PickBlend<true>(trace, features) : PickBlend<false>(trace, features);
    std::vector<std::vector<TileTraceEntry>> tile_traces(trace ? num_tiles : 0);
    std::vector<TileCounters> counters(num_tiles);
    tbb::parallel_for(tbb::blocked_range<int>(0, num_tiles, 1), [&](const tbb::blocked_range<int>& r) {
      thread_local TileState state;
      for (int t = r.begin(); t < r.end(); ++t) {
        blend(ctx, t, state, out, trace ? &tile_traces[t] : nullptr, counters[t]);
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
