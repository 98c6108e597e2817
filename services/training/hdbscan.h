// services/training/hdbscan.h: HDBSCAN* clustering (Campello, Moulavi, Sander 2013; the semantics
// of the `hdbscan` Python package, which the authors' final labelling calls through cuML):
// core distances to the min_samples-th nearest neighbour, the minimum spanning tree of the mutual
// reachability graph, its single-linkage hierarchy condensed by min_cluster_size, clusters chosen
// by excess of mass, then merged up to cluster_selection_epsilon; optionally the root as the single
// cluster. Exact and dense: O(n^2 d) time, O(n) memory beyond the points, so callers bound n
// (the labelling voxel-downsamples first). Deterministic for any thread count.
#pragma once

#include <cstdint>
#include <vector>

#include "absl/status/statusor.h"
#include "common/core/cancel.h"

namespace instascene::training {

struct HdbscanOptions {
  int min_samples = 30;                    // neighbours defining a point's core distance
  int min_cluster_size = 30;               // smaller splits are points falling out of a cluster
  double cluster_selection_epsilon = 0.1;  // clusters closer than this are merged (0 = off)
  bool allow_single_cluster = true;        // the root may be the one cluster
  int num_threads = 0;
  const CancelFlag* cancel = nullptr;
};

// One edge of the minimum spanning tree (mutual reachability distance).
struct MstEdge {
  uint32_t a = 0, b = 0;
  double distance = 0;
};

// Core distance of every point: the Euclidean distance to its k-th nearest other point.
std::vector<double> CoreDistances(const float* points, size_t n, int dim, int k, int num_threads);
// The minimum spanning tree of the mutual reachability graph max(core_a, core_b, |a - b|), by
// Prim's algorithm on the dense graph; n - 1 edges in the order they were added.
std::vector<MstEdge> MutualReachabilityMst(const float* points, size_t n, int dim,
                                           const std::vector<double>& core, int num_threads,
                                           const CancelFlag* cancel = nullptr);
// Cluster labels from an MST (any order): -1 = noise, clusters 0..k-1.
std::vector<int> ClustersFromMst(std::vector<MstEdge> mst, size_t n, const HdbscanOptions& options);

// Points are n rows of `dim` floats. InvalidArgument for n < 2 or bad options.
absl::StatusOr<std::vector<int>> Hdbscan(const float* points, size_t n, int dim,
                                         const HdbscanOptions& options);

}  // namespace instascene::training
