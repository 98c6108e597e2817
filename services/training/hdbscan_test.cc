// HDBSCAN against brute-force references: core distances by sorting every distance, the MST's total
// weight by Kruskal over all pairs, and clusterings whose right answer is known by construction.
#include "services/training/hdbscan.h"

#include "services/training/density_labels.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <numeric>
#include <random>
#include <set>

namespace instascene::training {
namespace {

std::vector<float> Blobs(const std::vector<std::vector<float>>& centres, int per_blob, float sigma,
                         int noise, uint64_t seed, int dim) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<float> g(0.0f, sigma);
  std::uniform_real_distribution<float> u(-3.0f, 3.0f);
  std::vector<float> p;
  for (const auto& c : centres)
    for (int i = 0; i < per_blob; ++i)
      for (int d = 0; d < dim; ++d) p.push_back(c[d] + g(rng));
  for (int i = 0; i < noise; ++i)
    for (int d = 0; d < dim; ++d) p.push_back(u(rng));
  return p;
}

double Dist(const float* a, const float* b, int dim) {
  double s = 0;
  for (int d = 0; d < dim; ++d) s += (a[d] - b[d]) * double(a[d] - b[d]);
  return std::sqrt(s);
}

TEST(Hdbscan, CoreDistancesAndMstMatchBruteForce) {
  const int dim = 5, n = 150;
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<float> u(0, 1);
  std::vector<float> p(n * dim);
  for (float& x : p) x = u(rng);
  const int k = 7;
  const std::vector<double> core = CoreDistances(p.data(), n, dim, k, 2);
  for (int i = 0; i < n; ++i) {
    std::vector<double> d;
    for (int j = 0; j < n; ++j)
      if (j != i) d.push_back(Dist(&p[i * dim], &p[j * dim], dim));
    std::sort(d.begin(), d.end());
    EXPECT_NEAR(core[i], d[k - 1], 1e-5) << i;
  }
  const std::vector<MstEdge> mst = MutualReachabilityMst(p.data(), n, dim, core, 2);
  ASSERT_EQ(mst.size(), size_t(n - 1));
  // Kruskal over every pair of the mutual reachability graph.
  struct E {
    double w;
    int a, b;
  };
  std::vector<E> edges;
  for (int a = 0; a < n; ++a)
    for (int b = a + 1; b < n; ++b)
      edges.push_back({std::max({core[a], core[b], Dist(&p[a * dim], &p[b * dim], dim)}), a, b});
  std::sort(edges.begin(), edges.end(), [](const E& x, const E& y) { return x.w < y.w; });
  std::vector<int> parent(n);
  std::iota(parent.begin(), parent.end(), 0);
  std::function<int(int)> find = [&](int x) {
    return parent[x] == x ? x : parent[x] = find(parent[x]);
  };
  double kruskal = 0;
  for (const E& e : edges) {
    const int a = find(e.a), b = find(e.b);
    if (a != b) {
      parent[a] = b;
      kruskal += e.w;
    }
  }
  double prim = 0;
  std::set<uint32_t> touched;
  for (const MstEdge& e : mst) {
    prim += e.distance;
    touched.insert(e.a);
    touched.insert(e.b);
  }
  EXPECT_NEAR(prim, kruskal, 1e-4);
  EXPECT_EQ(touched.size(), size_t(n));
  // The same tree for any thread count.
  const std::vector<MstEdge> one = MutualReachabilityMst(p.data(), n, dim, core, 1);
  for (size_t i = 0; i < mst.size(); ++i) {
    EXPECT_EQ(one[i].a, mst[i].a);
    EXPECT_EQ(one[i].b, mst[i].b);
  }
}

TEST(Hdbscan, SeparatedBlobsAreFoundAndScatteredPointsAreNoise) {
  const int dim = 3;
  const std::vector<std::vector<float>> centres = {{0, 0, 0}, {2, 0, 0}, {0, 2, 0}, {0, 0, 2}};
  const std::vector<float> p = Blobs(centres, 80, 0.05f, 20, 7, dim);
  HdbscanOptions o;
  o.min_samples = 10;
  o.min_cluster_size = 20;
  o.cluster_selection_epsilon = 0;
  o.allow_single_cluster = false;
  auto labels = Hdbscan(p.data(), p.size() / dim, dim, o);
  ASSERT_TRUE(labels.ok());
  // Each blob is one cluster, different from the others.
  std::set<int> ids;
  for (int b = 0; b < 4; ++b) {
    std::map<int, int> votes;
    for (int i = 0; i < 80; ++i) ++votes[(*labels)[b * 80 + i]];
    const auto best = std::max_element(votes.begin(), votes.end(),
                                       [](auto& x, auto& y) { return x.second < y.second; });
    EXPECT_NE(best->first, -1);
    EXPECT_GE(best->second, 76) << "blob " << b;
    ids.insert(best->first);
  }
  EXPECT_EQ(ids.size(), 4u);
  EXPECT_EQ(*std::max_element(labels->begin(), labels->end()), 3);
  int noise = 0;
  for (int i = 320; i < 340; ++i) noise += (*labels)[i] == -1;
  EXPECT_GE(noise, 15);  // scattered points are noise
}

TEST(Hdbscan, EpsilonMergesClustersCloserThanIt) {
  const int dim = 2;
  // Two pairs of blobs: inside a pair 0.3 apart, the pairs 5 apart.
  const std::vector<std::vector<float>> centres = {{0, 0}, {0.3f, 0}, {5, 0}, {5.3f, 0}};
  const std::vector<float> p = Blobs(centres, 60, 0.03f, 0, 11, dim);
  HdbscanOptions o;
  o.min_samples = 5;
  o.min_cluster_size = 15;
  o.allow_single_cluster = false;
  o.cluster_selection_epsilon = 0;
  auto fine = Hdbscan(p.data(), p.size() / dim, dim, o);
  o.cluster_selection_epsilon = 1.0;
  auto merged = Hdbscan(p.data(), p.size() / dim, dim, o);
  ASSERT_TRUE(fine.ok() && merged.ok());
  auto distinct = [](const std::vector<int>& l) {
    std::set<int> s(l.begin(), l.end());
    s.erase(-1);
    return s.size();
  };
  EXPECT_EQ(distinct(*fine), 4u);
  EXPECT_EQ(distinct(*merged), 2u);
  EXPECT_EQ((*merged)[0], (*merged)[60]);   // blobs 0 and 1 together
  EXPECT_NE((*merged)[0], (*merged)[120]);  // not with blob 2
}

TEST(Hdbscan, OneBlobIsASingleClusterOnlyWhenAllowed) {
  const int dim = 4;
  const std::vector<float> p = Blobs({{1, 1, 1, 1}}, 200, 0.1f, 0, 5, dim);
  HdbscanOptions o;
  o.min_samples = 10;
  o.min_cluster_size = 30;
  o.cluster_selection_epsilon = 0.5;
  o.allow_single_cluster = true;
  auto single = Hdbscan(p.data(), 200, dim, o);
  ASSERT_TRUE(single.ok());
  EXPECT_GE(std::count(single->begin(), single->end(), 0), 190);
  EXPECT_EQ(*std::max_element(single->begin(), single->end()), 0);
  EXPECT_FALSE(Hdbscan(p.data(), 1, dim, o).ok());
  o.min_cluster_size = 1;
  EXPECT_EQ(Hdbscan(p.data(), 200, dim, o).status().code(), absl::StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace instascene::training

namespace instascene::training {
namespace {

TEST(DensityLabels, GroupsWithDistinctFeaturesBecomeInstancesForAnyVoxelBudget) {
  // Three spatial groups of 600 Gaussians; the first two share one feature direction (one object
  // split in space by nothing: same instance), the third has its own.
  GaussianCloud cloud;
  cloud.Resize(1800);
  std::mt19937_64 rng(2);
  std::normal_distribution<float> g(0.0f, 0.02f);
  std::vector<float> features(1800 * 4, 0.0f);
  for (int i = 0; i < 1800; ++i) {
    const int group = i / 600;
    const float cx = group == 0 ? -1.0f : group == 1 ? -0.8f : 1.0f;
    cloud.positions[3 * i] = cx + 5 * g(rng);
    cloud.positions[3 * i + 1] = 5 * g(rng);
    cloud.positions[3 * i + 2] = 5 * g(rng);
    features[i * 4 + (group == 2 ? 1 : 0)] = 1.0f;
    for (int d = 0; d < 4; ++d) features[i * 4 + d] += g(rng);
  }
  for (int budget : {40000, 300}) {
    DensityLabelOptions o;
    o.max_points = budget;
    o.hdbscan.allow_single_cluster = false;
    auto labels = LabelByDensity(cloud, features, 4, o);
    ASSERT_TRUE(labels.ok()) << labels.status();
    EXPECT_LE(labels->clustered_points, size_t(budget));
    EXPECT_EQ(labels->clusters, 2u) << budget;
    std::vector<uint32_t> l = labels->labels;
    EXPECT_EQ(std::count(l.begin(), l.end(), 0u), 0);  // noise joins its nearest cluster
    EXPECT_EQ(std::count(l.begin(), l.begin() + 1200, l[0]), 1200) << budget;
    EXPECT_EQ(std::count(l.begin() + 1200, l.end(), l[1200]), 600) << budget;
    EXPECT_NE(l[0], l[1200]);
    o.hdbscan.num_threads = 1;
    EXPECT_EQ(LabelByDensity(cloud, features, 4, o)->labels, l);  // thread count never matters
  }
  EXPECT_EQ(LabelByDensity(cloud, std::vector<float>(10), 4, {}).status().code(),
            absl::StatusCode::kInvalidArgument);
}

// Clusters 5 and 6 are objects the decomposition found (instances 1 and 2 hold 3 of 5 and 2 of 3
// of them): their Gaussians the decomposition left as background (floor reached through shared
// voxels) return to the background. Cluster 7 is an object the decomposition missed, cluster 8
// one that no single instance holds half of: both keep everything.
TEST(DensityLabels, ClustersOfFoundObjectsGiveTheCoarseBackgroundBack) {
  const std::vector<uint32_t> coarse = {1, 1, 1, 0, 0, 2, 2, 0, 0, 0, 0, 1, 2, 0, 0};
  const std::vector<uint32_t> clusters = {5, 5, 5, 5, 5, 6, 6, 6, 7, 7, 7, 8, 8, 8, 8};
  std::vector<uint32_t> labels = clusters;
  EXPECT_EQ(ReturnCoarseBackground(coarse, 0.5, &labels), 3u);
  EXPECT_EQ(labels, (std::vector<uint32_t>{5, 5, 5, 0, 0, 6, 6, 0, 7, 7, 7, 8, 8, 8, 8}));
  labels = clusters;
  EXPECT_EQ(ReturnCoarseBackground(coarse, 0.0, &labels), 0u);  // off: the released code
  EXPECT_EQ(labels, clusters);
  labels = clusters;
  EXPECT_EQ(ReturnCoarseBackground(coarse, 0.25, &labels), 5u);  // cluster 8 too
}

}  // namespace
}  // namespace instascene::training
