// common/raster/depth_sort.h: the per-tile depth sort of the binning step (internal).
//
// A tile's keys are (depth bits << 32) | Gaussian index, appended in increasing index order. Depths
// are positive floats (beyond the near plane), whose bit patterns order like the values, so a
// stable LSD radix sort on the upper 32 bits gives exactly the order of sorting the whole keys:
// depth first, index for ties. Bytes every key shares are skipped (tiles often span one or two
// exponents), and short lists use std::sort.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <utility>

namespace instascene::raster_internal {

// Sorts keys[0, n) ascending. `scratch` holds at least n keys. Equal to std::sort of the keys when
// the low halves are distinct and ascending in input order, as the binning produces them.
inline void SortTileKeys(uint64_t* keys, size_t n, uint64_t* scratch) {
  // Below ~200 keys the radix passes' fixed cost (four 256-bucket histograms) loses to a
  // comparison sort (BM_SortTileKeys); the keys are distinct, so both give the same order.
  constexpr size_t kComparisonSortMax = 200;
  if (n <= kComparisonSortMax) {
    std::sort(keys, keys + n);
    return;
  }
  // One pass over the keys fills all four byte histograms of the depth bits.
  uint32_t histogram[4][256];
  std::memset(histogram, 0, sizeof(histogram));
  for (size_t i = 0; i < n; ++i) {
    const uint32_t depth = static_cast<uint32_t>(keys[i] >> 32);
    ++histogram[0][depth & 0xffu];
    ++histogram[1][(depth >> 8) & 0xffu];
    ++histogram[2][(depth >> 16) & 0xffu];
    ++histogram[3][depth >> 24];
  }
  uint64_t* from = keys;
  uint64_t* to = scratch;
  for (int pass = 0; pass < 4; ++pass) {
    uint32_t* counts = histogram[pass];
    const uint32_t first = static_cast<uint32_t>(from[0] >> (32 + 8 * pass)) & 0xffu;
    if (counts[first] == n) continue;  // every key has this byte: the pass would not move any
    uint32_t running = 0;
    for (int b = 0; b < 256; ++b) {
      const uint32_t c = counts[b];
      counts[b] = running;
      running += c;
    }
    const int shift = 32 + 8 * pass;
    for (size_t i = 0; i < n; ++i) {
      const uint64_t key = from[i];
      to[counts[(key >> shift) & 0xffu]++] = key;
    }
    std::swap(from, to);
  }
  if (from != keys) std::memcpy(keys, from, n * sizeof(uint64_t));
}

}  // namespace instascene::raster_internal
