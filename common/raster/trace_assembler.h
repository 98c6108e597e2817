// common/raster/trace_assembler.h: the rasterizer's contributor trace (render_types.h), built
// as a row-major CSR band by band while the tiles are blended. Internal to common/raster.
#pragma once

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <vector>

#if defined(__AVX__)
#include <immintrin.h>
#endif

#include "common/raster/projection.h"
#include "common/raster/render_types.h"
#include "common/raster/tile_blend.h"

namespace instascene::raster_internal {

// Copies `bytes` to `dst`, with non-temporal stores for the 32-byte-aligned middle: the trace
// arrays are far larger than the caches, so ordinary stores would first read every line they
// overwrite. StreamFence() orders the streamed stores before the task that wrote them ends.
inline void StreamCopy(void* dst, const void* src, size_t bytes) {
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
inline void StreamFence() {
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
      thread_local RawBuffer<Contribution> grouped;
      thread_local RawBuffer<float> grouped_t;
      grouped.Grow(tile.size);
      if (with_t_) grouped_t.Grow(tile.size);
      uint32_t cursor[kTilePixels];
      uint32_t running = 0;
      for (int local = 0; local < kTilePixels; ++local) {
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

}  // namespace instascene::raster_internal
