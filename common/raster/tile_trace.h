// common/raster/tile_trace.h: a tile's traced contributions as the blend kernel (tile_blend.h)
// appends them, in storage that persists in the workspace across frames (internal to the
// rasterizer).
#pragma once

#include <algorithm>
#include <cstdint>
#include <cstdlib>
#include <memory>
#include <new>

#include "common/raster/projection.h"
#include "common/raster/render_types.h"

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

}  // namespace instascene::raster_internal
