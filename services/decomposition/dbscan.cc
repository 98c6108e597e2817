#include "services/decomposition/dbscan.h"

#include <cmath>
#include <unordered_map>

#include "services/decomposition/union_find.h"

namespace instascene::decomposition {
namespace {

// Grid DBSCAN: cells of side eps / sqrt(3), so any two points of one cell are neighbours. A cell
// with >= min_points points makes all its points core without any query; other points count
// neighbours in the 5x5x5 surrounding cells with an early exit. Core cells are joined when some
// pair of their core points is within eps; border points take the cluster of their nearest core
// point. The core-point clusters are exactly DBSCAN's (border points, which DBSCAN assigns by
// visiting order, may differ).
class EpsGrid {
 public:
  EpsGrid(const std::vector<Eigen::Vector3f>& points, float eps) : cell_of(points.size()) {
    const float side = eps / std::sqrt(3.0f);
    for (uint32_t i = 0; i < points.size(); ++i) {
      const Eigen::Vector3i k(static_cast<int>(std::floor(points[i].x() / side)),
                              static_cast<int>(std::floor(points[i].y() / side)),
                              static_cast<int>(std::floor(points[i].z() / side)));
      auto [it, inserted] = cell_of_key_.try_emplace(k, static_cast<uint32_t>(cells.size()));
      if (inserted) {
        cells.emplace_back();
        keys_.push_back(k);
      }
      cells[it->second].push_back(i);
      cell_of[i] = it->second;
    }
  }

  // Calls fn(d) for every non-empty cell d within two cells of c (c included) until fn returns
  // false.
  template <typename Fn>
  void ForEachNeighbourCell(uint32_t c, Fn&& fn) const {
    for (int dx = -2; dx <= 2; ++dx) {
      for (int dy = -2; dy <= 2; ++dy) {
        for (int dz = -2; dz <= 2; ++dz) {
          auto it = cell_of_key_.find(keys_[c] + Eigen::Vector3i(dx, dy, dz));
          if (it != cell_of_key_.end() && !fn(it->second)) return;
        }
      }
    }
  }

  std::vector<std::vector<uint32_t>> cells;  // point indices, ascending
  std::vector<uint32_t> cell_of;             // per point

 private:
  struct KeyHash {
    size_t operator()(const Eigen::Vector3i& k) const {
      return static_cast<size_t>(k.x()) * 73856093u ^ static_cast<size_t>(k.y()) * 19349663u ^
             static_cast<size_t>(k.z()) * 83492791u;
    }
  };
  std::unordered_map<Eigen::Vector3i, uint32_t, KeyHash> cell_of_key_;
  std::vector<Eigen::Vector3i> keys_;
};

// Per point: at least min_points points (itself included) within eps.
std::vector<uint8_t> CoreFlags(const std::vector<Eigen::Vector3f>& points, const EpsGrid& grid,
                               float eps2, int min_points) {
  std::vector<uint8_t> core(points.size(), 0);
  for (uint32_t c = 0; c < grid.cells.size(); ++c) {
    if (static_cast<int>(grid.cells[c].size()) >= min_points) {
      for (uint32_t i : grid.cells[c]) core[i] = 1;
      continue;
    }
    for (uint32_t i : grid.cells[c]) {
      int count = 0;
      grid.ForEachNeighbourCell(c, [&](uint32_t d) {
        for (uint32_t j : grid.cells[d]) count += (points[i] - points[j]).squaredNorm() <= eps2;
        return count < min_points;
      });
      core[i] = count >= min_points;
    }
  }
  return core;
}

// Core cells joined where some pair of their core points lies within eps.
UnionFind JoinCoreCells(const std::vector<Eigen::Vector3f>& points, const EpsGrid& grid,
                        const std::vector<std::vector<uint32_t>>& core_points, float eps2) {
  UnionFind sets(grid.cells.size());
  for (uint32_t c = 0; c < grid.cells.size(); ++c) {
    if (core_points[c].empty()) continue;
    grid.ForEachNeighbourCell(c, [&](uint32_t d) {
      if (d <= c || core_points[d].empty() || sets.Find(c) == sets.Find(d)) return true;
      for (uint32_t i : core_points[c]) {
        for (uint32_t j : core_points[d]) {
          if ((points[i] - points[j]).squaredNorm() <= eps2) {
            sets.Union(c, d);
            return true;
          }
        }
      }
      return true;
    });
  }
  return sets;
}

}  // namespace

std::vector<int> Dbscan(const std::vector<Eigen::Vector3f>& points, float eps, int min_points) {
  const size_t n = points.size();
  std::vector<int> label(n, -1);
  if (n == 0) return label;
  const float eps2 = eps * eps;
  const EpsGrid grid(points, eps);
  const std::vector<uint8_t> core = CoreFlags(points, grid, eps2, min_points);
  std::vector<std::vector<uint32_t>> core_points(grid.cells.size());
  for (uint32_t c = 0; c < grid.cells.size(); ++c) {
    for (uint32_t i : grid.cells[c]) {
      if (core[i]) core_points[c].push_back(i);
    }
  }
  UnionFind sets = JoinCoreCells(points, grid, core_points, eps2);
  // Number clusters by their first core point in index order.
  std::vector<int> cluster_of_root(grid.cells.size(), -1);
  int next = 0;
  for (uint32_t i = 0; i < n; ++i) {
    if (!core[i]) continue;
    const uint32_t root = sets.Find(grid.cell_of[i]);
    if (cluster_of_root[root] < 0) cluster_of_root[root] = next++;
    label[i] = cluster_of_root[root];
  }
  for (uint32_t i = 0; i < n; ++i) {  // border points: the nearest core point within eps
    if (core[i]) continue;
    float best = eps2;
    int best_label = -1;
    grid.ForEachNeighbourCell(grid.cell_of[i], [&](uint32_t d) {
      for (uint32_t j : core_points[d]) {
        const float d2 = (points[i] - points[j]).squaredNorm();
        if (d2 <= best && (best_label < 0 || d2 < best)) {
          best = d2;
          best_label = label[j];
        }
      }
      return true;
    });
    label[i] = best_label;
  }
  return label;
}

}  // namespace instascene::decomposition
