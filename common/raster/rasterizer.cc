#include "common/raster/rasterizer.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>

#if defined(__AVX__)
#include <immintrin.h>
#endif

#include "absl/strings/str_cat.h"
#include "common/core/parallel.h"
#include "common/core/status.h"
#include "common/core/timer.h"
#include "common/raster/depth_sort.h"
#include "common/raster/projection.h"
#include "common/raster/tile_blend.h"

namespace instascene {
namespace {

using raster_internal::BlendTile;
using raster_internal::FrameContext;
using raster_internal::TileCounters;
using raster_internal::TileState;
using raster_internal::TileTrace;

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

// Copies `bytes` to `dst`, with non-temporal stores for the 32-byte-aligned middle: the trace
// arrays are far larger than the caches, so ordinary stores would first read every line they
// overwrite. StreamFence() orders the streamed stores before the task that wrote them ends.
void StreamCopy(void* dst, const void* src, size_t bytes) {
#if defined(__AVX__)
  char* d = static_cast<char*>(dst);
  const char* s = static_cast<const char*>(src);
  const size_t head = std::min(bytes, (32 - reinterpret_cast<uintptr_t>(d) % 32) % 32);
  std::memcpy(d, s, head);
  d += head;
  s += head;
  bytes -= head;
  for (; bytes >= 32; bytes -= 32, d += 32, s += 32) {
    _mm256_stream_si256(reinterpret_cast<__m256i*>(d),
                        _mm256_loadu_si256(reinterpret_cast<const __m256i*>(s)));
  }
  std::memcpy(d, s, bytes);
#else
  std::memcpy(dst, src, bytes);
#endif
}
void StreamFence() {
#if defined(__AVX__)
  _mm_sfence();
#endif
}

// Builds the row-major CSR trace band by band: a band is one row of tiles, i.e. 16 image rows,
// whose traced pixels are one contiguous stretch of CSR rows. Blending a band and scattering its
// tile lists right away keeps the staging lists in cache (a band's lists are a few MB) and needs
// staging for one band only; only the final entries go to memory.
class TraceAssembler {
 public:
  TraceAssembler(const ProjectionParams& p, const TraceOptions& options, ContributorTrace* trace)
      : p_(p), with_t_(options.transmittance), trace_(trace) {
    const size_t num_pixels = static_cast<size_t>(p.width) * p.height;
    all_pixels_ = options.pixels.empty();
    if (all_pixels_) {
      trace->pixels.resize(num_pixels);
      for (size_t i = 0; i < num_pixels; ++i) trace->pixels[i] = static_cast<uint32_t>(i);
    } else {
      trace->pixels = options.pixels;
      slot_.assign(num_pixels, -1);
      for (size_t i = 0; i < trace->pixels.size(); ++i)
        slot_[trace->pixels[i]] = static_cast<int64_t>(i);
    }
    // Every offset past the first is written by AddBand (the bands cover all CSR rows).
    trace->offsets.resize(trace->pixels.size() + 1);
    trace->offsets[0] = 0;
  }

  // Appends band `ty`; tiles[tx] holds the lists of tile (tx, ty).
  void AddBand(int ty, const std::vector<TileTrace>& tiles) {
    std::vector<uint64_t>& offsets = trace_->offsets;
    const size_t first_pix = static_cast<size_t>(ty) * kTileSize * p_.width;
    const size_t end_pix =
        std::min(static_cast<size_t>(ty + 1) * kTileSize, static_cast<size_t>(p_.height)) *
        p_.width;
    const size_t first_row = RowOf(first_pix), end_row = RowOf(end_pix);
    tbb::parallel_for(0, p_.tiles_x, [&](int tx) {
      ForEachPixel(tx, ty,
                   [&](int local, size_t row) { offsets[row + 1] = tiles[tx].counts[local]; });
    });
    for (size_t i = first_row + 1; i <= end_row; ++i) offsets[i] += offsets[i - 1];
    const size_t need = offsets[end_row];
    if (need > trace_->entries.size()) {
      if (need > trace_->entries.capacity())
        trace_->entries.reserve(std::max(need, 2 * trace_->entries.capacity()));
      trace_->entries.resize(need);
    }
    if (with_t_ && need > trace_->transmittance.size()) {
      if (need > trace_->transmittance.capacity())
        trace_->transmittance.reserve(std::max(need, 2 * trace_->transmittance.capacity()));
      trace_->transmittance.resize(need);
    }
    tbb::parallel_for(0, p_.tiles_x, [&](int tx) {
      // The tile's lists arrive splat by splat (pixels interleaved). Group them by pixel in a
      // per-thread buffer that stays in L2 (a counting sort keeps each pixel's front-to-back
      // order), then copy each tile row's pixels, which are consecutive CSR rows, in one
      // sequential run. Scattering straight into the frame-sized CSR was bound by the latency of
      // its cache misses; sequential runs stream at memory bandwidth.
      const TileTrace& tile = tiles[tx];
      thread_local raster_internal::RawBuffer<Contribution> grouped;
      thread_local raster_internal::RawBuffer<float> grouped_t;
      grouped.Grow(tile.size);
      if (with_t_) grouped_t.Grow(tile.size);
      uint32_t cursor[raster_internal::kTilePixels];
      uint32_t running = 0;
      for (int local = 0; local < raster_internal::kTilePixels; ++local) {
        cursor[local] = running;
        running += tile.counts[local];
      }
      Contribution* g = grouped.data();
      if (with_t_) {
        float* gt = grouped_t.data();
        for (size_t e = 0; e < tile.size; ++e) {
          const uint32_t at = cursor[tile.pixels[e]]++;
          g[at] = tile.entries[e];
          gt[at] = tile.transmittance[e];
        }
      } else {
        for (size_t e = 0; e < tile.size; ++e) g[cursor[tile.pixels[e]]++] = tile.entries[e];
      }
      // After the scatter, cursor[local] is the end of pixel `local`'s group. Untraced pixels
      // (a subset trace) have no entries, so each tile row's traced pixels form one run.
      ForEachTileRow(tx, ty, [&](int first_local, int end_local, size_t csr_row) {
        const uint32_t from = first_local == 0 ? 0 : cursor[first_local - 1];
        const uint32_t count = cursor[end_local - 1] - from;
        if (count == 0) return;
        const uint64_t to = offsets[csr_row];
        StreamCopy(trace_->entries.data() + to, g + from, count * sizeof(Contribution));
        if (with_t_) {
          StreamCopy(trace_->transmittance.data() + to, grouped_t.data() + from,
                     count * sizeof(float));
        }
      });
      StreamFence();
    });
    total_ = need;
  }

  // Trims the arrays to the final size (they may hold a larger previous frame's data).
  void Finish() {
    trace_->entries.resize(total_);
    trace_->transmittance.resize(with_t_ ? total_ : 0);
  }

 private:
  // The first CSR row whose pixel id is >= pix.
  size_t RowOf(size_t pix) const {
    if (all_pixels_) return pix;
    return static_cast<size_t>(
        std::lower_bound(trace_->pixels.begin(), trace_->pixels.end(), static_cast<uint32_t>(pix)) -
        trace_->pixels.begin());
  }
  // Calls fn(first local pixel, end local pixel, CSR row of the first traced pixel) for each
  // in-image row of tile (tx, ty) that holds a traced pixel.
  template <typename Fn>
  void ForEachTileRow(int tx, int ty, Fn&& fn) const {
    const int x1 = std::min(kTileSize, p_.width - tx * kTileSize),
              y1 = std::min(kTileSize, p_.height - ty * kTileSize);
    for (int ly = 0; ly < y1; ++ly) {
      const size_t pix = static_cast<size_t>(ty * kTileSize + ly) * p_.width + tx * kTileSize;
      if (all_pixels_) {
        fn(ly * kTileSize, ly * kTileSize + x1, pix);
        continue;
      }
      for (int lx = 0; lx < x1; ++lx) {
        if (slot_[pix + lx] >= 0) {
          fn(ly * kTileSize, ly * kTileSize + x1, static_cast<size_t>(slot_[pix + lx]));
          break;
        }
      }
    }
  }
  // Calls fn(local pixel, CSR row) for every traced in-image pixel of tile (tx, ty).
  template <typename Fn>
  void ForEachPixel(int tx, int ty, Fn&& fn) const {
    const int x1 = std::min(kTileSize, p_.width - tx * kTileSize),
              y1 = std::min(kTileSize, p_.height - ty * kTileSize);
    for (int ly = 0; ly < y1; ++ly) {
      for (int lx = 0; lx < x1; ++lx) {
        const size_t pix =
            static_cast<size_t>(ty * kTileSize + ly) * p_.width + tx * kTileSize + lx;
        const int64_t row = all_pixels_ ? static_cast<int64_t>(pix) : slot_[pix];
        if (row >= 0) fn(ly * kTileSize + lx, static_cast<size_t>(row));
      }
    }
  }

  const ProjectionParams& p_;
  bool all_pixels_ = true;
  const bool with_t_;
  ContributorTrace* trace_;
  std::vector<int64_t> slot_;  // pixel -> CSR row, for a pixel subset
  size_t total_ = 0;
};

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

absl::Status RenderInto(const GaussianCloud& cloud, const PinholeCamera& camera,
                        const RenderOptions& options, RenderResult* result) {
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
  // Every pixel of every buffer is overwritten below, so reused buffers need no clearing.
  RenderResult& out = *result;
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

  RasterWorkspace local_workspace;
  RasterWorkspace* ws = options.workspace != nullptr ? options.workspace : &local_workspace;
  RunWithThreads(options.num_threads, [&] {
    // 1. Project every Gaussian.
    Stopwatch phase;
    std::vector<ProjectedSplat>& splats = ws->splats;
    splats.resize(n);
    tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 4096),
                      [&](const tbb::blocked_range<size_t>& r) {
                        if (surfel) {
                          ProjectSurfels(cloud, r.begin(), r.size(), params, &splats[r.begin()],
                                         &out.visible[r.begin()]);
                          return;
                        }
                        for (size_t i = r.begin(); i < r.end(); ++i) {
                          out.visible[i] = ProjectEllipsoid(cloud, i, params, &splats[i]) ? 1 : 0;
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
      for (int c = 0; c < 3; ++c)
        ctx.world_from_camera[3 * r + c] = static_cast<float>(world_from_camera(r, c));
    }
    const bool trace = options.trace.enabled;
    const bool features = options.feature_dim > 0;
    BlendFn blend = surfel ? PickBlend<true>(options.trace, features)
                           : PickBlend<false>(options.trace, features);
    std::vector<TileCounters> counters(num_tiles);
    double assembly_ms = 0;
    if (!trace) {
      tbb::parallel_for(tbb::blocked_range<int>(0, num_tiles, 1),
                        [&](const tbb::blocked_range<int>& r) {
                          thread_local TileState state;
                          for (int t = r.begin(); t < r.end(); ++t)
                            blend(ctx, t, state, out, counters[t], nullptr);
                        });
    } else {
      // Band by band (one row of tiles): blend the band's tiles, then scatter their lists into
      // the CSR while they are still in cache.
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
    }
    for (const TileCounters& c : counters) {
      out.stats.evaluated_fragments += c.evaluated;
      out.stats.blended_fragments += c.blended;
    }
    out.stats.gaussian_tile_pairs = keys.size();
    out.stats.blend_ms = phase.ElapsedMs() - assembly_ms;
    out.stats.trace_assembly_ms = assembly_ms;
  });
  for (uint8_t v : out.visible) out.stats.visible_gaussians += v;
  out.stats.total_ms = total.ElapsedMs();
  return absl::OkStatus();
}

}  // namespace instascene
