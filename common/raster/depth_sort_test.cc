#include "common/raster/depth_sort.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <bit>
#include <random>
#include <vector>

namespace instascene::raster_internal {
namespace {

// Keys as the binning builds them: positive depths, ascending distinct indices.
std::vector<uint64_t> TileKeys(size_t n, float min_depth, float max_depth, int distinct_depths,
                               std::mt19937& rng) {
  std::uniform_real_distribution<float> depth(min_depth, max_depth);
  std::vector<float> pool(static_cast<size_t>(distinct_depths));
  for (float& d : pool) d = depth(rng);
  std::uniform_int_distribution<size_t> pick(0, pool.size() - 1);
  std::vector<uint64_t> keys(n);
  uint32_t index = 0;
  for (uint64_t& key : keys) {
    index += 1 + static_cast<uint32_t>(rng() % 5);
    key = (uint64_t{std::bit_cast<uint32_t>(pool[pick(rng)])} << 32) | index;
  }
  return keys;
}

TEST(DepthSort, MatchesStdSortOnRandomTiles) {
  std::mt19937 rng(7);
  for (int trial = 0; trial < 400; ++trial) {
    const size_t n = trial < 100 ? static_cast<size_t>(trial) : 1 + rng() % 5000;
    // Wide depth ranges span exponents (all four byte passes); narrow ones share high bytes;
    // few distinct depths give many ties, which must stay in index order.
    const float lo = trial % 3 == 0 ? 0.2f : 3.0f;
    const float hi = trial % 3 == 0 ? 500.0f : 3.01f;
    const int distinct = trial % 4 == 0 ? 3 : 100000;
    std::vector<uint64_t> keys = TileKeys(n, lo, hi, distinct, rng);
    std::vector<uint64_t> expected = keys;
    std::sort(expected.begin(), expected.end());
    std::vector<uint64_t> scratch(n);
    SortTileKeys(keys.data(), n, scratch.data());
    ASSERT_EQ(keys, expected) << "trial " << trial << ", n = " << n;
  }
}

TEST(DepthSort, AllEqualDepthsKeepInputOrder) {
  std::vector<uint64_t> keys;
  for (uint32_t i = 0; i < 1000; ++i)
    keys.push_back((uint64_t{std::bit_cast<uint32_t>(2.5f)} << 32) | i);
  const std::vector<uint64_t> expected = keys;
  std::vector<uint64_t> scratch(keys.size());
  SortTileKeys(keys.data(), keys.size(), scratch.data());
  EXPECT_EQ(keys, expected);
}

}  // namespace
}  // namespace instascene::raster_internal
