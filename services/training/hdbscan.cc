#include "services/training/hdbscan.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <numeric>
#include <set>

#include "absl/strings/str_cat.h"
#include "common/core/parallel.h"

namespace instascene::training {
namespace {

double SquaredDistance(const float* a, const float* b, int dim) {
  float s = 0;
  for (int d = 0; d < dim; ++d) {
    const float t = a[d] - b[d];
    s += t * t;
  }
  return s;
}

// A row of the single-linkage hierarchy: clusters `left` and `right` (ids < n are points, id n + i
// is the cluster made by row i) merge at `distance` into a cluster of `size` points.
struct Merge {
  size_t left, right;
  double distance;
  size_t size;
};

std::vector<Merge> SingleLinkage(std::vector<MstEdge> mst, size_t n) {
  std::stable_sort(mst.begin(), mst.end(),
                   [](const MstEdge& x, const MstEdge& y) { return x.distance < y.distance; });
  std::vector<size_t> parent(2 * n - 1), size(2 * n - 1, 1);
  std::iota(parent.begin(), parent.end(), size_t{0});
  auto find = [&](size_t x) {
    while (parent[x] != x) x = parent[x] = parent[parent[x]];
    return x;
  };
  std::vector<Merge> merges;
  merges.reserve(n - 1);
  for (const MstEdge& e : mst) {
    const size_t a = find(e.a), b = find(e.b);
    const size_t next = n + merges.size();
    merges.push_back({a, b, e.distance, size[a] + size[b]});
    parent[a] = parent[b] = next;
    size[next] = size[a] + size[b];
  }
  return merges;
}

// The condensed tree: rows (parent cluster, child, lambda = 1 / distance, child size), where a
// child below n is a point falling out of its cluster. Cluster ids start at n (the root).
struct CondensedRow {
  size_t parent, child;
  double lambda;
  size_t child_size;
};

// The points under a node of the single-linkage hierarchy (leaves are points 0..n-1).
void PointsUnder(const std::vector<Merge>& merges, size_t n, size_t node,
                 std::vector<size_t>* out) {
  std::vector<size_t> stack = {node};
  while (!stack.empty()) {
    const size_t x = stack.back();
    stack.pop_back();
    if (x < n) {
      out->push_back(x);
    } else {
      stack.push_back(merges[x - n].right);
      stack.push_back(merges[x - n].left);
    }
  }
}

std::vector<CondensedRow> Condense(const std::vector<Merge>& merges, size_t n,
                                   size_t min_cluster_size) {
  const size_t root = 2 * n - 2;
  auto count = [&](size_t node) { return node < n ? size_t{1} : merges[node - n].size; };
  std::vector<CondensedRow> rows;
  std::vector<size_t> relabel(2 * n - 1, 0);
  relabel[root] = n;
  size_t next_label = n + 1;
  // Breadth-first from the root over nodes that stay clusters.
  std::vector<size_t> queue = {root};
  for (size_t qi = 0; qi < queue.size(); ++qi) {
    const size_t node = queue[qi];
    const Merge& m = merges[node - n];
    const double lambda =
        m.distance > 0 ? 1.0 / m.distance : std::numeric_limits<double>::infinity();
    const size_t lc = count(m.left), rc = count(m.right);
    const size_t label = relabel[node];
    auto fall_out = [&](size_t child) {
      std::vector<size_t> points;
      PointsUnder(merges, n, child, &points);
      for (size_t p : points) rows.push_back({label, p, lambda, 1});
    };
    auto keep = [&](size_t child, size_t child_label) {
      relabel[child] = child_label;
      if (child >= n) queue.push_back(child);
    };
    if (lc >= min_cluster_size && rc >= min_cluster_size) {
      rows.push_back({label, next_label, lambda, lc});
      keep(m.left, next_label++);
      rows.push_back({label, next_label, lambda, rc});
      keep(m.right, next_label++);
    } else if (lc < min_cluster_size && rc < min_cluster_size) {
      fall_out(m.left);
      fall_out(m.right);
    } else if (lc < min_cluster_size) {
      fall_out(m.left);
      keep(m.right, label);  // the cluster goes on as the right child
    } else {
      fall_out(m.right);
      keep(m.left, label);
    }
  }
  return rows;
}

}  // namespace

std::vector<double> CoreDistances(const float* points, size_t n, int dim, int k, int num_threads) {
  std::vector<double> core(n, 0.0);
  if (n < 2) return core;
  const size_t kk = std::min<size_t>(static_cast<size_t>(std::max(k, 1)), n - 1);
  RunWithThreads(num_threads, [&] {
    tbb::parallel_for(
        tbb::blocked_range<size_t>(0, n, 64), [&](const tbb::blocked_range<size_t>& r) {
          std::vector<double> d(n);
          for (size_t i = r.begin(); i < r.end(); ++i) {
            for (size_t j = 0; j < n; ++j)
              d[j] = SquaredDistance(points + i * dim, points + j * dim, dim);
            // d[i] = 0 is the smallest: the kk-th other point is at sorted index kk.
            std::nth_element(d.begin(), d.begin() + static_cast<std::ptrdiff_t>(kk), d.end());
            core[i] = std::sqrt(d[kk]);
          }
        });
  });
  return core;
}

std::vector<MstEdge> MutualReachabilityMst(const float* points, size_t n, int dim,
                                           const std::vector<double>& core, int num_threads,
                                           const CancelFlag* cancel) {
  std::vector<MstEdge> mst;
  if (n < 2) return mst;
  mst.reserve(n - 1);
  constexpr double kInf = std::numeric_limits<double>::infinity();
  std::vector<double> best(n, kInf);  // squared mutual reachability to the tree
  std::vector<uint32_t> from(n, 0);
  std::vector<char> in_tree(n, 0);
  std::vector<double> core2(n);
  for (size_t i = 0; i < n; ++i) core2[i] = core[i] * core[i];
  struct Best {
    double value;
    size_t index;
  };
  size_t current = 0;
  in_tree[0] = 1;
  RunWithThreads(num_threads, [&] {
    for (size_t added = 1; added < n; ++added) {
      if (IsCancelled(cancel)) return;
      const float* c = points + current * dim;
      const double cc = core2[current];
      // Relax every outside point through `current`, and find the closest one (ties: lowest index,
      // so the result does not depend on how the range is split).
      const Best next = tbb::parallel_reduce(
          tbb::blocked_range<size_t>(0, n, 2048), Best{kInf, n},
          [&](const tbb::blocked_range<size_t>& r, Best acc) {
            for (size_t j = r.begin(); j < r.end(); ++j) {
              if (in_tree[j]) continue;
              const double mr = std::max({cc, core2[j], SquaredDistance(c, points + j * dim, dim)});
              if (mr < best[j]) {
                best[j] = mr;
                from[j] = static_cast<uint32_t>(current);
              }
              if (best[j] < acc.value || (best[j] == acc.value && j < acc.index))
                acc = {best[j], j};
            }
            return acc;
          },
          [](const Best& x, const Best& y) {
            return x.value < y.value || (x.value == y.value && x.index < y.index) ? x : y;
          });
      in_tree[next.index] = 1;
      mst.push_back({from[next.index], static_cast<uint32_t>(next.index), std::sqrt(next.value)});
      current = next.index;
    }
  });
  return mst;
}

namespace {

// The condensed tree's clusters (ids root..max_cluster, index id - root): each one's birth lambda,
// stability, parent and the children that are clusters.
struct ClusterTree {
  size_t root = 0;
  size_t max_cluster = 0;
  std::vector<double> birth, stability;
  std::vector<std::vector<size_t>> children;
  std::vector<size_t> parent;

  size_t size() const { return max_cluster - root + 1; }
  // Calls f on every cluster below `c` (not c itself).
  template <typename F>
  void ForEachDescendant(size_t c, F f) const {
    std::vector<size_t> stack(children[c - root].begin(), children[c - root].end());
    while (!stack.empty()) {
      const size_t x = stack.back();
      stack.pop_back();
      f(x);
      for (size_t y : children[x - root]) stack.push_back(y);
    }
  }
};

ClusterTree BuildClusterTree(const std::vector<CondensedRow>& tree, size_t n) {
  ClusterTree t;
  t.root = n;
  t.max_cluster = t.root;
  for (const CondensedRow& r : tree) t.max_cluster = std::max({t.max_cluster, r.parent, r.child});
  const size_t clusters = t.size();
  t.birth.assign(clusters, 0.0);
  t.stability.assign(clusters, 0.0);
  t.children.resize(clusters);
  t.parent.assign(clusters, 0);
  for (const CondensedRow& r : tree) {
    if (r.child >= t.root) {
      t.birth[r.child - t.root] = r.lambda;
      t.children[r.parent - t.root].push_back(r.child);
      t.parent[r.child - t.root] = r.parent;
    }
  }
  for (const CondensedRow& r : tree) {
    const double birth = t.birth[r.parent - t.root];
    const double lambda = std::isinf(r.lambda) ? birth : r.lambda;
    t.stability[r.parent - t.root] += (lambda - birth) * static_cast<double>(r.child_size);
  }
  return t;
}

// Excess of mass: from the leaves up, a cluster is selected unless its children together are
// more stable (their sum becomes its stability).
std::vector<char> SelectByExcessOfMass(ClusterTree& t, bool allow_single_cluster) {
  const size_t root = t.root;
  std::vector<char> selected(t.size(), 0);
  std::vector<size_t> order(t.size());
  std::iota(order.begin(), order.end(), root);
  std::sort(order.rbegin(), order.rend());  // children have larger ids than their parents
  for (size_t c : order) {
    if (c == root && !allow_single_cluster) continue;
    double subtree = 0;
    for (size_t child : t.children[c - root]) subtree += t.stability[child - root];
    if (!t.children[c - root].empty() && subtree > t.stability[c - root]) {
      t.stability[c - root] = subtree;
    } else {
      selected[c - root] = 1;
      t.ForEachDescendant(c, [&](size_t x) { selected[x - root] = 0; });
    }
  }
  // The root cannot be chosen unless allowed; if nothing below it was, there is no cluster.
  if (!allow_single_cluster) selected[0] = 0;
  return selected;
}

// Epsilon: a selected cluster born closer than epsilon is replaced by its nearest ancestor born
// at a distance above epsilon (never the root unless single clusters are allowed); a chosen
// ancestor absorbs chosen clusters below it.
void ApplySelectionEpsilon(const ClusterTree& t, double eps, bool allow_single_cluster,
                           std::vector<char>* selected) {
  const size_t root = t.root;
  std::set<size_t> chosen;
  std::vector<char> processed(t.size(), 0);
  for (size_t c = root + 1; c <= t.max_cluster; ++c) {
    if (!(*selected)[c - root]) continue;
    if (1.0 / t.birth[c - root] >= eps) {
      chosen.insert(c);
      continue;
    }
    if (processed[c - root]) continue;
    size_t node = c;
    while (true) {
      const size_t parent = t.parent[node - root];
      if (parent == root) {
        node = allow_single_cluster ? root : node;
        break;
      }
      node = parent;
      if (1.0 / t.birth[parent - root] > eps) break;
    }
    chosen.insert(node);
    t.ForEachDescendant(node, [&](size_t x) { processed[x - root] = 1; });
  }
  std::fill(selected->begin(), selected->end(), 0);
  for (size_t c : chosen) {
    bool covered = false;
    for (size_t a = c; a != root && !covered;) {
      a = t.parent[a - root];
      covered = chosen.count(a) > 0;
    }
    if (!covered) (*selected)[c - root] = 1;
  }
}

// Labels: each point joins the selected cluster it fell out of or below; ids in cluster order.
std::vector<int> LabelPoints(const std::vector<CondensedRow>& tree, const ClusterTree& t,
                             const std::vector<char>& selected, double eps, size_t n) {
  const size_t root = t.root;
  std::vector<int> labels(n, -1);
  std::vector<int> id(t.size(), -1);
  int next_id = 0;
  for (size_t c = 0; c < t.size(); ++c)
    if (selected[c]) id[c] = next_id++;
  auto selected_ancestor = [&](size_t c) -> int {
    for (;; c = t.parent[c - root]) {
      if (selected[c - root]) return static_cast<int>(c);
      if (c == root) return -1;
    }
  };
  double root_max_lambda = 0;
  for (const CondensedRow& r : tree)
    if (r.parent == root && r.child < root) root_max_lambda = std::max(root_max_lambda, r.lambda);
  for (const CondensedRow& r : tree) {
    if (r.child >= root) continue;
    const int c = selected_ancestor(r.parent);
    if (c < 0) continue;
    if (static_cast<size_t>(c) == root) {
      // The root as the single cluster keeps only points that stay until the densest level
      // (or, with epsilon, below the epsilon distance), as the reference implementation.
      const bool keep = eps > 0 ? r.lambda >= 1.0 / eps : r.lambda >= root_max_lambda;
      if (!keep) continue;
    }
    labels[r.child] = id[c - root];
  }
  return labels;
}

}  // namespace

std::vector<int> ClustersFromMst(std::vector<MstEdge> mst, size_t n,
                                 const HdbscanOptions& options) {
  if (n < 2 || mst.size() != n - 1) return std::vector<int>(n, -1);
  const std::vector<Merge> merges = SingleLinkage(std::move(mst), n);
  const std::vector<CondensedRow> tree =
      Condense(merges, n, static_cast<size_t>(std::max(options.min_cluster_size, 2)));
  ClusterTree clusters = BuildClusterTree(tree, n);
  std::vector<char> selected = SelectByExcessOfMass(clusters, options.allow_single_cluster);
  const double eps = options.cluster_selection_epsilon;
  const bool only_root = selected[0] && std::count(selected.begin(), selected.end(), 1) == 1;
  if (eps > 0 && clusters.size() > 1 && !only_root) {
    ApplySelectionEpsilon(clusters, eps, options.allow_single_cluster, &selected);
  }
  return LabelPoints(tree, clusters, selected, eps, n);
}

absl::StatusOr<std::vector<int>> Hdbscan(const float* points, size_t n, int dim,
                                         const HdbscanOptions& options) {
  if (n < 2) return absl::InvalidArgumentError(absl::StrCat("hdbscan: ", n, " points"));
  if (dim < 1) return absl::InvalidArgumentError("hdbscan: dimension must be >= 1");
  if (options.min_samples < 1 || options.min_cluster_size < 2 ||
      !(options.cluster_selection_epsilon >= 0))
    return absl::InvalidArgumentError(
        "hdbscan: need min_samples >= 1, min_cluster_size >= 2, epsilon >= 0");
  const std::vector<double> core =
      CoreDistances(points, n, dim, options.min_samples, options.num_threads);
  if (IsCancelled(options.cancel)) return absl::CancelledError("hdbscan: cancelled");
  std::vector<MstEdge> mst =
      MutualReachabilityMst(points, n, dim, core, options.num_threads, options.cancel);
  if (IsCancelled(options.cancel)) return absl::CancelledError("hdbscan: cancelled");
  return ClustersFromMst(std::move(mst), n, options);
}

}  // namespace instascene::training
