// common/raster/fast_exp.h: a branch-free exp for x <= 0 that compilers vectorise.
//
// Cephes-style: range reduction by ln 2 (split in two constants), a degree-6 minimax polynomial,
// and the power of two built in the exponent bits. Max relative error about 2e-7 (1-2 ulp) on
// [-87, 0]; inputs below -87 clamp to exp(-87) ~ 1.6e-38 (the rasterizer discards any alpha below
// 1/255 long before). Pure function, thread-safe.
#pragma once

#include <bit>
#include <cmath>
#include <cstdint>

namespace instascene {

inline float FastExpNonPositive(float x) {
  x = x < -87.0f ? -87.0f : (x > 0.0f ? 0.0f : x);
  const float n = std::floor(x * 1.44269504088896341f + 0.5f);
  float r = x - n * 0.693359375f;
  r = r - n * -2.12194440e-4f;
  float p = 1.9875691500e-4f;
  p = p * r + 1.3981999507e-3f;
  p = p * r + 8.3334519073e-3f;
  p = p * r + 4.1665795894e-2f;
  p = p * r + 1.6666665459e-1f;
  p = p * r + 5.0000001201e-1f;
  const float y = p * r * r + r + 1.0f;
  const int32_t bits = (static_cast<int32_t>(n) + 127) << 23;
  return y * std::bit_cast<float>(bits);
}

}  // namespace instascene
