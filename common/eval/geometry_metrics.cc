#include "common/eval/geometry_metrics.h"

#include <algorithm>
#include <cmath>
#include <random>

#include "common/geometry/point_index.h"

namespace instascene {

PointCloudComparison ComparePointClouds(const std::vector<Eigen::Vector3f>& predicted,
                                        const std::vector<Eigen::Vector3f>& ground_truth,
                                        double tau) {
  PointCloudComparison out;
  if (predicted.empty() || ground_truth.empty()) return out;
  const PointIndex3 pred_index(predicted), gt_index(ground_truth);
  double to_gt = 0, to_pred = 0;
  size_t close_pred = 0, close_gt = 0;
  for (const Eigen::Vector3f& p : predicted) {
    const double d = std::sqrt(static_cast<double>(gt_index.Nearest(p).second));
    to_gt += d;
    close_pred += d <= tau;
  }
  for (const Eigen::Vector3f& q : ground_truth) {
    const double d = std::sqrt(static_cast<double>(pred_index.Nearest(q).second));
    to_pred += d;
    close_gt += d <= tau;
  }
  out.chamfer = 0.5 * (to_gt / predicted.size() + to_pred / ground_truth.size());
  out.precision = static_cast<double>(close_pred) / predicted.size();
  out.recall = static_cast<double>(close_gt) / ground_truth.size();
  out.f1 = out.precision + out.recall > 0
               ? 2 * out.precision * out.recall / (out.precision + out.recall)
               : 0.0;
  return out;
}

namespace {

// Where the line {(t, py, pz)} crosses triangle abc (barycentric coordinates of (py, pz) in the
// triangle's yz projection); false when it misses or the projection is degenerate.
bool CrossingX(const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c,
               double py, double pz, double* x) {
  const double d = (b.y() - a.y()) * (c.z() - a.z()) - (c.y() - a.y()) * (b.z() - a.z());
  if (d == 0.0) return false;
  const double u = ((py - a.y()) * (c.z() - a.z()) - (c.y() - a.y()) * (pz - a.z())) / d;
  const double v = ((b.y() - a.y()) * (pz - a.z()) - (py - a.y()) * (b.z() - a.z())) / d;
  if (u < 0 || v < 0 || u + v > 1) return false;
  *x = a.x() + u * (b.x() - a.x()) + v * (c.x() - a.x());
  return true;
}

}  // namespace

std::vector<uint8_t> VoxelizeClosedMesh(const TriangleMesh& mesh, const Eigen::AlignedBox3f& box,
                                        int resolution) {
  const int r = resolution;
  std::vector<uint8_t> inside(static_cast<size_t>(r) * r * r, 0);
  const Eigen::Vector3f cell = box.sizes() / static_cast<float>(r);
  // Row (j, k) casts a ray along +x through voxel centres; the tiny offset keeps rays off mesh
  // vertices and edges that sit exactly on grid-aligned coordinates (parity must not double count).
  constexpr double kOffset = 0.5 + 1.3e-4;
  auto row_y = [&](int j) { return box.min().y() + (j + kOffset) * cell.y(); };
  auto row_z = [&](int k) { return box.min().z() + (k + kOffset) * cell.z(); };
  std::vector<std::vector<double>> hits(static_cast<size_t>(r) * r);
  for (const auto& t : mesh.triangles) {
    const Eigen::Vector3d a = mesh.vertices[t[0]].cast<double>(),
                          b = mesh.vertices[t[1]].cast<double>(),
                          c = mesh.vertices[t[2]].cast<double>();
    const double ymin = std::min({a.y(), b.y(), c.y()}), ymax = std::max({a.y(), b.y(), c.y()});
    const double zmin = std::min({a.z(), b.z(), c.z()}), zmax = std::max({a.z(), b.z(), c.z()});
    const int j0 =
        std::max(0, static_cast<int>(std::floor((ymin - box.min().y()) / cell.y() - kOffset)));
    const int j1 =
        std::min(r - 1, static_cast<int>(std::ceil((ymax - box.min().y()) / cell.y() - kOffset)));
    const int k0 =
        std::max(0, static_cast<int>(std::floor((zmin - box.min().z()) / cell.z() - kOffset)));
    const int k1 =
        std::min(r - 1, static_cast<int>(std::ceil((zmax - box.min().z()) / cell.z() - kOffset)));
    for (int j = j0; j <= j1; ++j) {
      for (int k = k0; k <= k1; ++k) {
        double x;
        if (CrossingX(a, b, c, row_y(j), row_z(k), &x)) {
          hits[static_cast<size_t>(j) * r + k].push_back(x);
        }
      }
    }
  }
  for (int j = 0; j < r; ++j) {
    for (int k = 0; k < r; ++k) {
      std::vector<double>& xs = hits[static_cast<size_t>(j) * r + k];
      std::sort(xs.begin(), xs.end());
      for (size_t h = 0; h + 1 < xs.size(); h += 2) {  // inside between entry and exit crossings
        for (int i = 0; i < r; ++i) {
          const double px = box.min().x() + (i + 0.5) * cell.x();
          if (px >= xs[h] && px <= xs[h + 1]) inside[(static_cast<size_t>(i) * r + j) * r + k] = 1;
        }
      }
    }
  }
  return inside;
}

double VolumeIou(const TriangleMesh& a, const TriangleMesh& b, int resolution) {
  Eigen::AlignedBox3f box = a.Bounds();
  box.extend(b.Bounds());
  if (box.isEmpty()) return 0.0;
  // A margin of one cell so surface voxels are not clipped.
  const Eigen::Vector3f pad = box.sizes() / static_cast<float>(resolution);
  box.min() -= pad;
  box.max() += pad;
  const std::vector<uint8_t> va = VoxelizeClosedMesh(a, box, resolution),
                             vb = VoxelizeClosedMesh(b, box, resolution);
  size_t inter = 0, uni = 0;
  for (size_t i = 0; i < va.size(); ++i) {
    inter += va[i] && vb[i];
    uni += va[i] || vb[i];
  }
  return uni == 0 ? 0.0 : static_cast<double>(inter) / static_cast<double>(uni);
}

std::vector<Eigen::Vector3f> SampleSurface(const TriangleMesh& mesh, size_t count, uint64_t seed) {
  std::vector<Eigen::Vector3f> out;
  if (mesh.triangles.empty()) return out;
  std::vector<double> cdf(mesh.triangles.size());
  double total = 0;
  for (size_t t = 0; t < mesh.triangles.size(); ++t) cdf[t] = (total += mesh.TriangleArea(t));
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> uni(0, 1);
  out.reserve(count);
  for (size_t s = 0; s < count; ++s) {
    const size_t t =
        std::min(static_cast<size_t>(std::lower_bound(cdf.begin(), cdf.end(), uni(rng) * total) -
                                     cdf.begin()),
                 mesh.triangles.size() - 1);
    double r1 = uni(rng), r2 = uni(rng);
    if (r1 + r2 > 1) {
      r1 = 1 - r1;
      r2 = 1 - r2;
    }
    const auto& tri = mesh.triangles[t];
    out.push_back(((1 - r1 - r2) * mesh.vertices[tri[0]].cast<double>() +
                   r1 * mesh.vertices[tri[1]].cast<double>() +
                   r2 * mesh.vertices[tri[2]].cast<double>())
                      .cast<float>());
  }
  return out;
}

}  // namespace instascene
