// common/raster/simd8.h: 8-lane float and int vectors for the tile blending kernel
// (tile_blend.h; internal to the rasterizer): loads and stores, lane masks, compression of the
// set lanes, fused multiply-add where the target has it, and exp for x <= 0.
#pragma once

#include <cstdint>
#include <cstring>

#if defined(__AVX__) || defined(__FMA__)
#include <immintrin.h>
#endif

namespace instascene::raster_internal {

// 8-lane vectors (GCC/Clang vector extensions: AVX2 where available, SSE pairs otherwise). Every
// lane computes exactly what the scalar formula computes; nothing is fused or reassociated.
inline constexpr int kLanes = 8;
using v8f = float __attribute__((vector_size(32)));
using v8i = int32_t __attribute__((vector_size(32)));
inline constexpr v8i kLaneIndex = {0, 1, 2, 3, 4, 5, 6, 7};
inline v8f Splat(float v) { return v8f{v, v, v, v, v, v, v, v}; }
inline v8i SplatI(int32_t v) { return v8i{v, v, v, v, v, v, v, v}; }
inline v8f Load(const float* p) {
  v8f v;
  std::memcpy(&v, p, sizeof(v));
  return v;
}
inline v8i LoadI(const int32_t* p) {
  v8i v;
  std::memcpy(&v, p, sizeof(v));
  return v;
}
inline void Store(float* p, v8f v) { std::memcpy(p, &v, sizeof(v)); }
inline void StoreI(int32_t* p, v8i v) { std::memcpy(p, &v, sizeof(v)); }
inline int SumLanes(v8i v) { return v[0] + v[1] + v[2] + v[3] + v[4] + v[5] + v[6] + v[7]; }
// Bit l set where lane l of the mask is true.
inline uint32_t MaskBits(v8i mask) {
#if defined(__AVX__)
  __m256 m;
  std::memcpy(&m, &mask, sizeof(m));
  return static_cast<uint32_t>(_mm256_movemask_ps(m));
#else
  uint32_t bits = 0;
  for (int l = 0; l < kLanes; ++l) bits |= static_cast<uint32_t>(mask[l] & 1) << l;
  return bits;
#endif
}

// Lane permutations that move the set lanes of an 8-bit mask to the front, in lane order (a
// compress, which AVX2 lacks as an instruction): kCompress[bits] for Permute.
struct CompressTable {
  int32_t perm[256][8];
  constexpr CompressTable() : perm() {
    for (int bits = 0; bits < 256; ++bits) {
      int n = 0;
      for (int l = 0; l < kLanes; ++l) {
        if (bits & (1 << l)) perm[bits][n++] = l;
      }
      for (; n < kLanes; ++n) perm[bits][n] = 0;
    }
  }
};
inline constexpr CompressTable kCompress{};

// (v[index[0]], ..., v[index[7]]): a lane permutation by a run-time index vector (AVX2 vpermd).
// Written with intrinsics, not GCC's __builtin_shuffle, so that Clang (clang-tidy) parses it too.
inline v8i Permute(v8i v, v8i index) {
#if defined(__AVX2__)
  return std::bit_cast<v8i>(
      _mm256_permutevar8x32_epi32(std::bit_cast<__m256i>(v), std::bit_cast<__m256i>(index)));
#else
  v8i out;
  for (int l = 0; l < kLanes; ++l) out[l] = v[index[l] & (kLanes - 1)];
  return out;
#endif
}

// a * b + c, fused where the target has FMA (the polynomial below is evaluated with whichever; its
// accuracy bound holds for both).
inline v8f MulAdd(v8f a, v8f b, v8f c) {
#if defined(__FMA__)
  __m256 ma, mb, mc;
  std::memcpy(&ma, &a, sizeof(ma));
  std::memcpy(&mb, &b, sizeof(mb));
  std::memcpy(&mc, &c, sizeof(mc));
  const __m256 r = _mm256_fmadd_ps(ma, mb, mc);
  v8f out;
  std::memcpy(&out, &r, sizeof(out));
  return out;
#else
  return a * b + c;
#endif
}

// exp(x) for x <= 0 on 8 lanes (Cephes expf: range reduction by ln 2 split in two constants, a
// degree-6 polynomial, the power of two built in the exponent bits; max relative error ~2e-7).
// Inputs below -87 clamp to exp(-87) ~ 1.6e-38, far below the 1/255 alpha threshold. Rounding to
// nearest uses the 1.5 * 2^23 trick.
inline v8f FastExpNonPositive8(v8f x) {
  x = x < Splat(-87.0f) ? Splat(-87.0f) : x;
  x = x > Splat(0.0f) ? Splat(0.0f) : x;
  const v8f magic = Splat(12582912.0f);
  const v8f n = (x * Splat(1.44269504088896341f) + magic) - magic;
  v8f r = MulAdd(n, Splat(-0.693359375f), x);
  r = MulAdd(n, Splat(2.12194440e-4f), r);
  v8f p = Splat(1.9875691500e-4f);
  p = MulAdd(p, r, Splat(1.3981999507e-3f));
  p = MulAdd(p, r, Splat(8.3334519073e-3f));
  p = MulAdd(p, r, Splat(4.1665795894e-2f));
  p = MulAdd(p, r, Splat(1.6666665459e-1f));
  p = MulAdd(p, r, Splat(5.0000001201e-1f));
  const v8f y = MulAdd(p, r * r, r + Splat(1.0f));
  const v8i bits = (__builtin_convertvector(n, v8i) + SplatI(127)) << 23;
  v8f scale;
  std::memcpy(&scale, &bits, sizeof(scale));
  return y * scale;
}

}  // namespace instascene::raster_internal
