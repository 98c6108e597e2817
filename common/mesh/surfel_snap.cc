#include "common/mesh/surfel_snap.h"

#include <algorithm>
#include <cmath>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "common/geometry/point_index.h"

namespace instascene {
namespace {

// Area-weighted vertex normals, pointing out of the volume the mesh encloses (by the sign of its
// signed volume; an open mesh keeps its winding's side).
std::vector<Eigen::Vector3f> OutwardVertexNormals(const TriangleMesh& mesh) {
  std::vector<Eigen::Vector3f> normals(mesh.vertices.size(), Eigen::Vector3f::Zero());
  double volume = 0;
  for (const auto& t : mesh.triangles) {
    const Eigen::Vector3f& a = mesh.vertices[t[0]];
    const Eigen::Vector3f& b = mesh.vertices[t[1]];
    const Eigen::Vector3f& c = mesh.vertices[t[2]];
    const Eigen::Vector3f n = (b - a).cross(c - a);
    for (uint32_t v : t) normals[v] += n;
    volume += a.cast<double>().dot(b.cast<double>().cross(c.cast<double>()));
  }
  const float sign = volume < 0 ? -1.0f : 1.0f;
  for (Eigen::Vector3f& n : normals) {
    const float length = n.norm();
    n = length > 0 ? Eigen::Vector3f(sign * n / length) : Eigen::Vector3f::Zero();
  }
  return normals;
}

// `passes` times, each value becomes the mean over its vertex and the vertex's 1-ring (`zero`
// where `is_fixed`).
template <typename T, typename Fixed>
void SmoothOverRings(const std::vector<std::vector<uint32_t>>& ring, const Fixed& is_fixed,
                     int passes, const T& zero, std::vector<T>* values) {
  for (int pass = 0; pass < passes; ++pass) {
    std::vector<T> next(values->size(), zero);
    for (size_t v = 0; v < values->size(); ++v) {
      if (is_fixed(v)) continue;
      T sum = (*values)[v];
      for (uint32_t u : ring[v]) sum += (*values)[u];
      next[v] = sum / static_cast<float>(1 + ring[v].size());
    }
    values->swap(next);
  }
}

}  // namespace

size_t SnapToSurfels(const std::vector<Eigen::Vector3f>& points,
                     const std::vector<Eigen::Vector3f>& normals, const SurfelSnapOptions& options,
                     TriangleMesh* mesh, const std::vector<uint8_t>& fixed) {
  if (points.empty() || mesh->vertices.empty() || options.radius <= 0 || options.max_move <= 0) {
    return 0;
  }
  const std::vector<Eigen::Vector3f> vertex_normals = OutwardVertexNormals(*mesh);
  const PointIndex3 index(points);
  const size_t n = mesh->vertices.size();
  auto is_fixed = [&fixed](size_t v) { return v < fixed.size() && fixed[v]; };
  const int min_surfels = std::max(1, options.min_surfels);
  // Each vertex's signed move along its normal (0 where too few surfels face its way).
  std::vector<float> move(n, 0.0f);
  std::vector<uint8_t> snapped(n, 0);
  const float tangential_var = 0.25f * options.radius * options.radius;
  tbb::parallel_for(
      tbb::blocked_range<size_t>(0, n, 256), [&](const tbb::blocked_range<size_t>& r) {
        std::vector<std::pair<float, float>> facing;  // (offset along the normal, weight)
        for (size_t v = r.begin(); v != r.end(); ++v) {
          const Eigen::Vector3f& p = mesh->vertices[v];
          const Eigen::Vector3f& nv = vertex_normals[v];
          if (nv.isZero() || is_fixed(v)) continue;
          facing.clear();
          for (uint32_t i : index.WithinRadius(p, options.radius)) {
            if (std::abs(normals[i].dot(nv)) < options.min_cos) continue;
            const Eigen::Vector3f d = points[i] - p;
            const float along = d.dot(nv);
            const float tangential_sq = std::max(0.0f, d.squaredNorm() - along * along);
            facing.emplace_back(along, std::exp(-0.5f * tangential_sq / tangential_var));
          }
          if (static_cast<int>(facing.size()) < min_surfels) continue;
          // The outermost layer: surfels within `layer` of the min_surfels-th outermost one (fewer
          // stray surfels standing farther out do not define it, nor count in it).
          std::nth_element(facing.begin(), facing.begin() + (min_surfels - 1), facing.end(),
                           [](const auto& a, const auto& b) { return a.first > b.first; });
          const float outer = facing[min_surfels - 1].first;
          double sum = 0, weight = 0;
          for (const auto& [along, w] : facing) {
            if (std::abs(along - outer) > options.layer) continue;
            sum += w * along;
            weight += w;
          }
          if (weight <= 0) continue;
          move[v] =
              std::clamp(static_cast<float>(sum / weight), -options.max_move, options.max_move);
          snapped[v] = 1;
        }
      });
  // Smooth the moves over each vertex's 1-ring (a vertex that did not snap counts as not moving).
  std::vector<std::vector<uint32_t>> ring(n);
  for (const auto& t : mesh->triangles) {
    for (int k = 0; k < 3; ++k) {
      ring[t[k]].push_back(t[(k + 1) % 3]);
      ring[t[k]].push_back(t[(k + 2) % 3]);
    }
  }
  SmoothOverRings(ring, is_fixed, options.smooth_passes, 0.0f, &move);
  size_t moved = 0;
  for (size_t v = 0; v < n; ++v) {
    mesh->vertices[v] += move[v] * vertex_normals[v];
    moved += snapped[v];
  }
  if (options.reach <= 0) return moved;
  std::vector<Eigen::Vector3f> pull(n, Eigen::Vector3f::Zero());
  tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 256),
                    [&](const tbb::blocked_range<size_t>& r) {
                      for (size_t v = r.begin(); v != r.end(); ++v) {
                        const auto [nearest, dist_sq] = index.Nearest(mesh->vertices[v]);
                        const float dist = std::sqrt(dist_sq);
                        if (dist <= options.reach || is_fixed(v)) continue;
                        const float length = std::min(dist - options.reach, options.max_move);
                        pull[v] = length / dist * (points[nearest] - mesh->vertices[v]);
                      }
                    });
  SmoothOverRings(ring, is_fixed, options.smooth_passes, Eigen::Vector3f::Zero().eval(), &pull);
  for (size_t v = 0; v < n; ++v) {
    mesh->vertices[v] += pull[v];
    moved += !snapped[v] && !pull[v].isZero();
  }
  return moved;
}

}  // namespace instascene
