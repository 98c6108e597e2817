// common/raster/simd_math.h: 4-lane float exp/log and 4-lane double helpers for the batched
// projection (internal to the rasterizer). GCC/Clang vector extensions; AVX instructions where
// the target has them, element-wise fallbacks otherwise. Every lane computes the same thing as a
// one-lane call, so results never depend on how Gaussians are grouped.
#pragma once

#include <bit>
#include <cmath>
#include <cstdint>

#if defined(__AVX__)
#include <immintrin.h>
#endif

namespace instascene::raster_internal {

using v4f = float __attribute__((vector_size(16)));
using v4i = int32_t __attribute__((vector_size(16)));
using v4d = double __attribute__((vector_size(32)));
using v4l = int64_t __attribute__((vector_size(32)));

inline v4f Splat4f(float v) { return v4f{v, v, v, v}; }
inline v4i Splat4i(int32_t v) { return v4i{v, v, v, v}; }
inline v4d Splat4d(double v) { return v4d{v, v, v, v}; }

// exp(x), Cephes expf: x clamped to [-87, 88], range reduction by ln 2 split in two constants, a
// degree-5 polynomial in the remainder, the power of two built in the exponent bits. Relative
// error below 2.5e-7 (tested against std::exp).
inline v4f Exp4f(v4f x) {
  x = x < Splat4f(-87.0f) ? Splat4f(-87.0f) : x;
  x = x > Splat4f(88.0f) ? Splat4f(88.0f) : x;
  const v4f magic = Splat4f(12582912.0f);  // 1.5 * 2^23: adding it rounds to an integer
  const v4f n = (x * Splat4f(1.44269504088896341f) + magic) - magic;
  v4f r = x - n * Splat4f(0.693359375f);
  r = r + n * Splat4f(2.12194440e-4f);
  v4f p = Splat4f(1.9875691500e-4f);
  p = p * r + Splat4f(1.3981999507e-3f);
  p = p * r + Splat4f(8.3334519073e-3f);
  p = p * r + Splat4f(4.1665795894e-2f);
  p = p * r + Splat4f(1.6666665459e-1f);
  p = p * r + Splat4f(5.0000001201e-1f);
  const v4f y = p * (r * r) + (r + Splat4f(1.0f));
  const v4i bits = (__builtin_convertvector(n, v4i) + Splat4i(127)) << 23;
  return y * std::bit_cast<v4f>(bits);
}

// log(x), Cephes logf: x = m 2^e with m in [sqrt(1/2), sqrt(2)), a degree-8 polynomial in m - 1.
// Relative error below 2.5e-7 for normal positive x (tested against std::log); -inf for x <= 0
// and subnormal x (callers only compare the result with 0 there).
inline v4f Log4f(v4f x) {
  const v4i bits = std::bit_cast<v4i>(x);
  const v4i exponent_field = (bits >> 23) & Splat4i(0xff);
  v4f e = __builtin_convertvector(exponent_field - Splat4i(126), v4f);
  v4f m = std::bit_cast<v4f>((bits & Splat4i(0x007fffff)) | Splat4i(0x3f000000));  // [0.5, 1)
  const v4i small = m < Splat4f(0.707106781186547524f);
  e = small ? e - Splat4f(1.0f) : e;
  m = small ? m + m - Splat4f(1.0f) : m - Splat4f(1.0f);
  const v4f z = m * m;
  v4f y = Splat4f(7.0376836292e-2f);
  y = y * m + Splat4f(-1.1514610310e-1f);
  y = y * m + Splat4f(1.1676998740e-1f);
  y = y * m + Splat4f(-1.2420140846e-1f);
  y = y * m + Splat4f(1.4249322787e-1f);
  y = y * m + Splat4f(-1.6668057665e-1f);
  y = y * m + Splat4f(2.0000714765e-1f);
  y = y * m + Splat4f(-2.4999993993e-1f);
  y = y * m + Splat4f(3.3333331174e-1f);
  y = y * m * z;
  y = y + e * Splat4f(-2.12194440e-4f);
  y = y - Splat4f(0.5f) * z;
  v4f result = m + y;
  result = result + e * Splat4f(0.693359375f);
  const v4i invalid = (x <= Splat4f(0.0f)) | (exponent_field == Splat4i(0));
  return invalid ? Splat4f(-INFINITY) : result;
}

inline v4d Sqrt4d(v4d x) {
#if defined(__AVX__)
  return std::bit_cast<v4d>(_mm256_sqrt_pd(std::bit_cast<__m256d>(x)));
#else
  for (int l = 0; l < 4; ++l) x[l] = std::sqrt(x[l]);
  return x;
#endif
}
inline v4d Floor4d(v4d x) {
#if defined(__AVX__)
  return std::bit_cast<v4d>(_mm256_floor_pd(std::bit_cast<__m256d>(x)));
#else
  for (int l = 0; l < 4; ++l) x[l] = std::floor(x[l]);
  return x;
#endif
}
inline v4d Ceil4d(v4d x) {
#if defined(__AVX__)
  return std::bit_cast<v4d>(_mm256_ceil_pd(std::bit_cast<__m256d>(x)));
#else
  for (int l = 0; l < 4; ++l) x[l] = std::ceil(x[l]);
  return x;
#endif
}
// std::max(a, b) and std::min(a, b) lane by lane (same operand order, same NaN behaviour).
inline v4d Max4d(v4d a, v4d b) { return a < b ? b : a; }
inline v4d Min4d(v4d a, v4d b) { return b < a ? b : a; }
inline v4d ToDouble(v4f x) { return __builtin_convertvector(x, v4d); }
inline v4f ToFloat(v4d x) { return __builtin_convertvector(x, v4f); }

}  // namespace instascene::raster_internal
