#include "common/raster/simd_math.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

namespace instascene::raster_internal {
namespace {

TEST(SimdMath, Exp4fMatchesStdExp) {
  std::mt19937 rng(1);
  std::uniform_real_distribution<float> uni(-87.0f, 88.0f);
  double worst = 0;
  for (int trial = 0; trial < 200000; ++trial) {
    v4f x;
    for (int l = 0; l < 4; ++l)
      x[l] = trial < 4 ? static_cast<float>(trial * 4 + l) * 0.5f - 4 : uni(rng);
    const v4f y = Exp4f(x);
    for (int l = 0; l < 4; ++l) {
      const double want = std::exp(static_cast<double>(x[l]));
      worst = std::max(worst, std::abs(y[l] - want) / want);
    }
  }
  EXPECT_LT(worst, 2.5e-7);
  // Clamped outside [-87, 88]: finite, positive, monotone.
  const v4f far = Exp4f(v4f{-1000.0f, -88.0f, 89.0f, 1000.0f});
  EXPECT_GT(far[0], 0.0f);
  EXPECT_LE(far[0], far[1]);
  EXPECT_TRUE(std::isfinite(far[3]));
  EXPECT_NEAR(Exp4f(Splat4f(0.0f))[0], 1.0f, 0.0f);
}

TEST(SimdMath, Log4fMatchesStdLog) {
  std::mt19937 rng(2);
  std::uniform_real_distribution<float> exponent(-125.0f, 127.0f);
  double worst = 0;
  for (int trial = 0; trial < 200000; ++trial) {
    v4f x;
    for (int l = 0; l < 4; ++l) x[l] = std::exp2(exponent(rng));
    const v4f y = Log4f(x);
    for (int l = 0; l < 4; ++l) {
      const double want = std::log(static_cast<double>(x[l]));
      // Relative where |log x| is large, absolute near x = 1 (where log x -> 0).
      worst = std::max(worst, std::abs(y[l] - want) / std::max(1.0, std::abs(want)));
    }
  }
  EXPECT_LT(worst, 2.5e-7);
  const v4f edge = Log4f(v4f{0.0f, -1.0f, 1e-40f, 1.0f});
  EXPECT_EQ(edge[0], -INFINITY);
  EXPECT_EQ(edge[1], -INFINITY);
  EXPECT_EQ(edge[2], -INFINITY);
  EXPECT_EQ(edge[3], 0.0f);
}

TEST(SimdMath, DoubleHelpersMatchScalar) {
  const v4d x{-2.5, 0.49, 3.0, 1e-300};
  const v4d s = Sqrt4d(v4d{4.0, 2.0, 0.0, 1e-4});
  EXPECT_EQ(s[0], 2.0);
  EXPECT_EQ(s[1], std::sqrt(2.0));
  EXPECT_EQ(s[2], 0.0);
  EXPECT_EQ(s[3], std::sqrt(1e-4));
  for (int l = 0; l < 4; ++l) {
    EXPECT_EQ(Floor4d(x)[l], std::floor(x[l]));
    EXPECT_EQ(Ceil4d(x)[l], std::ceil(x[l]));
    EXPECT_EQ(Max4d(Splat4d(0.5), x)[l], std::max(0.5, x[l]));
    EXPECT_EQ(Min4d(Splat4d(0.5), x)[l], std::min(0.5, x[l]));
  }
}

}  // namespace
}  // namespace instascene::raster_internal
