#include "services/objects/convex_decomposition.h"

#include <algorithm>
#include <array>
#include <queue>

#include "absl/strings/str_cat.h"
#include "common/core/status.h"
#include "common/mesh/mesh_volume.h"
#include "services/objects/convex_hull.h"
#include "services/objects/mass_properties.h"

namespace instascene::objects {
namespace {

using Cell = std::array<int, 3>;

struct Grid {
  Eigen::Vector3f origin;
  float size = 0;  // voxel edge
  int n = 0;
  std::vector<uint8_t> inside;
  bool In(const Cell& c) const {
    for (int a = 0; a < 3; ++a)
      if (c[a] < 0 || c[a] >= n) return false;
    return inside[(static_cast<size_t>(c[2]) * n + c[1]) * n + c[0]] != 0;
  }
};

struct Part {
  std::vector<Cell> cells;
  TriangleMesh hull;
  double hull_volume = 0;
  double concavity = 0;  // 1 - voxel volume / hull volume
  bool final = false;    // no split makes it better
};

// The hull of the corners of the part's boundary cells (interior cells add no extreme point).
absl::StatusOr<Part> MakePart(std::vector<Cell> cells, const Grid& grid) {
  std::vector<uint8_t> mark(grid.inside.size(), 0);
  auto index = [&](const Cell& c) {
    return (static_cast<size_t>(c[2]) * grid.n + c[1]) * grid.n + c[0];
  };
  for (const Cell& c : cells) mark[index(c)] = 1;
  auto member = [&](Cell c) {
    for (int a = 0; a < 3; ++a)
      if (c[a] < 0 || c[a] >= grid.n) return false;
    return mark[index(c)] != 0;
  };
  std::vector<Eigen::Vector3f> corners;
  for (const Cell& c : cells) {
    bool boundary = false;
    for (int a = 0; a < 3 && !boundary; ++a)
      for (int d : {-1, 1}) {
        Cell nb = c;
        nb[a] += d;
        if (!member(nb)) boundary = true;
      }
    if (!boundary) continue;
    for (int corner = 0; corner < 8; ++corner)
      corners.push_back(grid.origin + grid.size * Eigen::Vector3f(c[0] + (corner & 1),
                                                                  c[1] + ((corner >> 1) & 1),
                                                                  c[2] + ((corner >> 2) & 1)));
  }
  std::sort(corners.begin(), corners.end(), [](const Eigen::Vector3f& a, const Eigen::Vector3f& b) {
    return std::lexicographical_compare(a.data(), a.data() + 3, b.data(), b.data() + 3);
  });
  corners.erase(std::unique(corners.begin(), corners.end()), corners.end());
  Part part;
  ASSIGN_OR_RETURN(part.hull, ConvexHull(corners));
  part.hull_volume = MeshMassProperties(part.hull).volume;
  const double voxels = static_cast<double>(cells.size()) * grid.size * grid.size * grid.size;
  part.concavity = part.hull_volume > 0 ? 1.0 - voxels / part.hull_volume : 0.0;
  part.cells = std::move(cells);
  return part;
}

// Connected components (6-neighbourhood) of a set of cells.
std::vector<std::vector<Cell>> Components(const std::vector<Cell>& cells, const Grid& grid) {
  std::vector<int> label(grid.inside.size(), -1);
  auto index = [&](const Cell& c) {
    return (static_cast<size_t>(c[2]) * grid.n + c[1]) * grid.n + c[0];
  };
  std::vector<uint8_t> member(grid.inside.size(), 0);
  for (const Cell& c : cells) member[index(c)] = 1;
  std::vector<std::vector<Cell>> out;
  for (const Cell& seed : cells) {
    if (label[index(seed)] >= 0) continue;
    const int id = static_cast<int>(out.size());
    out.emplace_back();
    std::vector<Cell> stack = {seed};
    label[index(seed)] = id;
    while (!stack.empty()) {
      const Cell c = stack.back();
      stack.pop_back();
      out.back().push_back(c);
      for (int a = 0; a < 3; ++a)
        for (int d : {-1, 1}) {
          Cell nb = c;
          nb[a] += d;
          if (nb[a] < 0 || nb[a] >= grid.n) continue;
          const size_t i = index(nb);
          if (member[i] && label[i] < 0) {
            label[i] = id;
            stack.push_back(nb);
          }
        }
    }
  }
  return out;
}

// The mesh's voxel grid: a cube of resolution^3 around its box, one voxel of margin, inside by
// ray parity.
absl::StatusOr<Grid> VoxelGrid(const TriangleMesh& mesh, int resolution) {
  Eigen::AlignedBox3f box;
  for (const Eigen::Vector3f& v : mesh.vertices) box.extend(v);
  Grid grid;
  grid.n = resolution;
  grid.size = box.sizes().maxCoeff() / static_cast<float>(grid.n - 2);
  grid.origin = box.center() - Eigen::Vector3f::Constant(0.5f * grid.size * grid.n);
  const Eigen::AlignedBox3f cube(grid.origin,
                                 grid.origin + Eigen::Vector3f::Constant(grid.size * grid.n));
  ASSIGN_OR_RETURN(grid.inside, VoxelizeByRayParity(mesh, cube, grid.n));
  return grid;
}

// The part whose hull wastes the most volume, if it is not convex enough; -1 when none.
int WorstPart(const std::vector<Part>& parts, double max_concavity) {
  int worst = -1;
  double worst_waste = 0;
  for (size_t p = 0; p < parts.size(); ++p) {
    const double waste = parts[p].concavity * parts[p].hull_volume;
    if (!parts[p].final && parts[p].concavity > max_concavity && parts[p].cells.size() >= 8 &&
        waste > worst_waste) {
      worst = static_cast<int>(p);
      worst_waste = waste;
    }
  }
  return worst;
}

// The cut of `part` along an axis at one of split_candidates planes whose halves' hulls (their
// connected components') hold the least volume, if less than the part's own hull; empty if none.
std::vector<Part> BestSplit(const Part& part, const Grid& grid, int split_candidates) {
  double best_cost = part.hull_volume;
  std::vector<Part> best;
  for (int axis = 0; axis < 3; ++axis) {
    int lo = grid.n, hi = -1;
    for (const Cell& c : part.cells) {
      lo = std::min(lo, c[axis]);
      hi = std::max(hi, c[axis]);
    }
    for (int s = 1; s <= split_candidates; ++s) {
      const int cut = lo + (hi - lo + 1) * s / (split_candidates + 1);
      if (cut <= lo || cut > hi) continue;
      std::vector<Cell> below, above;
      for (const Cell& c : part.cells) (c[axis] < cut ? below : above).push_back(c);
      std::vector<Part> halves;
      double cost = 0;
      for (auto* half : {&below, &above})
        for (std::vector<Cell>& component : Components(*half, grid)) {
          absl::StatusOr<Part> piece = MakePart(std::move(component), grid);
          if (!piece.ok()) continue;  // a flat sliver: covered by its neighbour's hull
          cost += piece->hull_volume;
          halves.push_back(*std::move(piece));
        }
      if (!halves.empty() && cost < best_cost - 1e-12) {
        best_cost = cost;
        best = std::move(halves);
      }
    }
  }
  return best;
}

}  // namespace

absl::Status ConvexDecompositionOptions::Validate() const {
  if (resolution < 4 || resolution > 256)
    return absl::InvalidArgumentError("decomposition resolution must be in [4, 256]");
  if (max_parts < 1 || max_parts > 256)
    return absl::InvalidArgumentError("max_parts must be in [1, 256]");
  if (!(max_concavity >= 0 && max_concavity < 1))
    return absl::InvalidArgumentError("max_concavity must be in [0, 1)");
  if (split_candidates < 1 || split_candidates > 64)
    return absl::InvalidArgumentError("split_candidates must be in [1, 64]");
  return absl::OkStatus();
}

absl::StatusOr<std::vector<TriangleMesh>> ConvexDecomposition(
    const TriangleMesh& mesh, const ConvexDecompositionOptions& options) {
  RETURN_IF_ERROR(options.Validate());
  if (mesh.triangles.empty()) return absl::InvalidArgumentError("empty mesh: nothing to decompose");
  ASSIGN_OR_RETURN(const Grid grid, VoxelGrid(mesh, options.resolution));
  std::vector<Cell> all;
  for (int k = 0; k < grid.n; ++k)
    for (int j = 0; j < grid.n; ++j)
      for (int i = 0; i < grid.n; ++i)
        if (grid.In({i, j, k})) all.push_back({i, j, k});
  if (all.empty()) {  // thinner than a voxel: the hull of the surface
    ASSIGN_OR_RETURN(TriangleMesh hull, ConvexHull(mesh.vertices));
    return std::vector<TriangleMesh>{std::move(hull)};
  }
  std::vector<Part> parts;
  for (std::vector<Cell>& component : Components(all, grid)) {
    absl::StatusOr<Part> part = MakePart(std::move(component), grid);
    if (part.ok()) parts.push_back(*std::move(part));  // a one-voxel-thin sliver spans no volume
  }
  while (static_cast<int>(parts.size()) < options.max_parts) {
    const int worst = WorstPart(parts, options.max_concavity);
    if (worst < 0) break;
    std::vector<Part> best =
        BestSplit(parts[static_cast<size_t>(worst)], grid, options.split_candidates);
    if (best.empty() || static_cast<int>(parts.size() + best.size()) - 1 > options.max_parts) {
      parts[static_cast<size_t>(worst)].final = true;
      continue;
    }
    parts.erase(parts.begin() + worst);
    for (Part& p : best) parts.push_back(std::move(p));
  }
  std::vector<TriangleMesh> out;
  for (Part& p : parts) out.push_back(std::move(p.hull));
  return out;
}

}  // namespace instascene::objects
