#include "services/decomposition/union_find.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <random>
#include <vector>

namespace instascene::decomposition {
namespace {

// Against a brute-force reference: components by graph search over the unions' edges, numbered
// in the order of their smallest members; the same whatever order the unions come in.
TEST(UnionFind, ComponentsMatchAGraphSearchAndIgnoreTheUnionOrder) {
  constexpr uint32_t kN = 300;
  std::mt19937 rng(7);
  std::uniform_int_distribution<uint32_t> pick(0, kN - 1);
  std::vector<std::pair<uint32_t, uint32_t>> edges(220);
  for (auto& e : edges) e = {pick(rng), pick(rng)};
  std::vector<std::vector<uint32_t>> adjacent(kN);
  for (const auto& [a, b] : edges) {
    adjacent[a].push_back(b);
    adjacent[b].push_back(a);
  }
  std::vector<int> expected(kN, -1);
  int sets = 0;
  for (uint32_t seed = 0; seed < kN; ++seed) {
    if (expected[seed] >= 0) continue;
    std::vector<uint32_t> stack = {seed};
    expected[seed] = sets;
    while (!stack.empty()) {
      const uint32_t x = stack.back();
      stack.pop_back();
      for (uint32_t y : adjacent[x]) {
        if (expected[y] < 0) {
          expected[y] = sets;
          stack.push_back(y);
        }
      }
    }
    ++sets;
  }
  for (int order = 0; order < 3; ++order) {
    UnionFind uf(kN);
    int joined = 0;
    for (const auto& [a, b] : edges) joined += uf.Union(a, b);
    EXPECT_EQ(joined, static_cast<int>(kN) - sets);  // each join removes one set
    const std::vector<uint32_t> components = uf.Components();
    for (uint32_t x = 0; x < kN; ++x) {
      ASSERT_EQ(components[x], static_cast<uint32_t>(expected[x])) << x;
      // The root is the smallest member.
      const uint32_t root = uf.Find(x);
      EXPECT_LE(root, x);
      EXPECT_EQ(components[root], components[x]);
    }
    std::shuffle(edges.begin(), edges.end(), rng);
  }
}

}  // namespace
}  // namespace instascene::decomposition
