#include "services/decomposition/dbscan.h"

#include <random>

#include <gtest/gtest.h>

namespace instascene::decomposition {
namespace {

TEST(Dbscan, SplitsClustersAndDropsFloaters) {
  std::mt19937 rng(3);
  std::normal_distribution<float> n(0.0f, 0.01f);
  std::vector<Eigen::Vector3f> points;
  for (int i = 0; i < 60; ++i) points.emplace_back(n(rng), n(rng), n(rng));
  for (int i = 0; i < 60; ++i) points.emplace_back(1.0f + n(rng), n(rng), n(rng));
  points.emplace_back(0.5f, 0.5f, 0.5f);  // floaters
  points.emplace_back(-0.7f, 0.2f, 0.0f);
  const std::vector<int> label = Dbscan(points, 0.05f, 4);
  for (int i = 1; i < 60; ++i) EXPECT_EQ(label[i], label[0]);
  for (int i = 61; i < 120; ++i) EXPECT_EQ(label[i], label[60]);
  EXPECT_NE(label[0], label[60]);
  EXPECT_GE(label[0], 0);
  EXPECT_EQ(label[120], -1);
  EXPECT_EQ(label[121], -1);
}

// Textbook O(n^2) DBSCAN core-point clustering: the reference for the grid implementation.
std::vector<int> BruteCoreClusters(const std::vector<Eigen::Vector3f>& p, float eps,
                                   int min_points) {
  const size_t n = p.size();
  std::vector<uint8_t> core(n, 0);
  for (size_t i = 0; i < n; ++i) {
    int count = 0;
    for (size_t j = 0; j < n; ++j) count += (p[i] - p[j]).norm() <= eps;
    core[i] = count >= min_points;
  }
  std::vector<int> label(n, -1);
  int next = 0;
  for (size_t i = 0; i < n; ++i) {
    if (!core[i] || label[i] >= 0) continue;
    std::vector<size_t> stack = {i};
    label[i] = next;
    while (!stack.empty()) {
      const size_t a = stack.back();
      stack.pop_back();
      for (size_t b = 0; b < n; ++b) {
        if (core[b] && label[b] < 0 && (p[a] - p[b]).norm() <= eps) {
          label[b] = next;
          stack.push_back(b);
        }
      }
    }
    ++next;
  }
  return label;
}

TEST(Dbscan, GridMatchesBruteForceOnCorePoints) {
  std::mt19937 rng(21);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  for (int trial = 0; trial < 6; ++trial) {
    std::vector<Eigen::Vector3f> p;
    for (int c = 0; c < 5; ++c) {  // blobs of varying density plus uniform clutter
      const Eigen::Vector3f center(u(rng), u(rng), u(rng));
      const float spread = 0.02f + 0.05f * u(rng);
      for (int i = 0; i < 80; ++i)
        p.push_back(center + spread * Eigen::Vector3f(u(rng) - 0.5f, u(rng) - 0.5f, u(rng) - 0.5f));
    }
    for (int i = 0; i < 100; ++i) p.emplace_back(u(rng), u(rng), u(rng));
    const float eps = 0.03f + 0.02f * trial;
    const std::vector<int> fast = Dbscan(p, eps, 4), ref = BruteCoreClusters(p, eps, 4);
    for (size_t i = 0; i < p.size(); ++i) {
      if (ref[i] >= 0) {
        EXPECT_EQ(fast[i], ref[i]) << "core point " << i << " trial " << trial;
      }
      // A non-core point is noise exactly when no core point lies within eps.
      bool near_core = false;
      for (size_t j = 0; j < p.size(); ++j) near_core |= ref[j] >= 0 && (p[i] - p[j]).norm() <= eps;
      EXPECT_EQ(fast[i] >= 0, ref[i] >= 0 || near_core) << i;
    }
  }
}

}  // namespace
}  // namespace instascene::decomposition
