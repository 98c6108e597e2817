#include "common/mesh/surfel_snap.h"

#include <algorithm>
#include <cmath>
#include <functional>
#include <optional>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "common/geometry/point_index.h"

namespace instascene {
namespace {

// A fixed vertex whose normal has less than this across the slide normal (sin of ~17 degrees)
// does not slide: the inside of a flat base.
constexpr float kMinAcross = 0.3f;
// A sliding vertex's layer is extrapolated to its height where the layer's heights spread by at
// least this share of the neighbourhood's radius (standard deviation 0.1 radius).
constexpr float kMinRiseSpread = 0.01f;

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

// `passes` times, each value becomes the mean over its vertex and those of the vertex's 1-ring
// not `left_out` (`zero` where `stays`).
template <typename T, typename Stays, typename LeftOut>
void SmoothOverRings(const std::vector<std::vector<uint32_t>>& ring, const Stays& stays,
                     const LeftOut& left_out, int passes, const T& zero, std::vector<T>* values) {
  for (int pass = 0; pass < passes; ++pass) {
    std::vector<T> next(values->size(), zero);
    for (size_t v = 0; v < values->size(); ++v) {
      if (stays(v)) continue;
      T sum = (*values)[v];
      int count = 1;
      for (uint32_t u : ring[v]) {
        if (left_out(u)) continue;
        sum += (*values)[u];
        ++count;
      }
      next[v] = sum / static_cast<float>(count);
    }
    values->swap(next);
  }
}

// A fixed vertex slides along its normal's part across `slide_normal` (none where that part is
// short: the inside of a flat base, whose normal is the slide normal; none without a slide).
void SlideDirections(const std::vector<uint8_t>& fixed, const Eigen::Vector3f& slide_normal,
                     std::vector<Eigen::Vector3f>* vertex_normals) {
  for (size_t v = 0; v < vertex_normals->size() && v < fixed.size(); ++v) {
    if (!fixed[v]) continue;
    Eigen::Vector3f& n = (*vertex_normals)[v];
    Eigen::Vector3f across = Eigen::Vector3f::Zero();
    if (!slide_normal.isZero()) {
      across = n - n.dot(slide_normal) * slide_normal;
      across = across.norm() >= kMinAcross ? across.normalized() : Eigen::Vector3f::Zero();
    }
    n = across;
  }
}

struct Facing {
  float along, weight, rise;  // offset along the normal, weight, height along the slide
};

// The signed move of the vertex at `p` along `nv` onto the outermost layer of the surfels that
// face its way; nullopt where fewer than min_surfels do.
std::optional<float> SnapOffset(const Eigen::Vector3f& p, const Eigen::Vector3f& nv, bool sliding,
                                const PointIndex3& index,
                                const std::vector<Eigen::Vector3f>& points,
                                const std::vector<Eigen::Vector3f>& normals,
                                const SurfelSnapOptions& options, std::vector<Facing>& facing) {
  const int min_surfels = std::max(1, options.min_surfels);
  const float tangential_var = 0.25f * options.radius * options.radius;
  facing.clear();
  for (uint32_t i : index.WithinRadius(p, options.radius)) {
    if (std::abs(normals[i].dot(nv)) < options.min_cos) continue;
    const Eigen::Vector3f d = points[i] - p;
    const float along = d.dot(nv);
    const float tangential_sq = std::max(0.0f, d.squaredNorm() - along * along);
    facing.push_back(
        {along, std::exp(-0.5f * tangential_sq / tangential_var), d.dot(options.slide_normal)});
  }
  if (static_cast<int>(facing.size()) < min_surfels) return std::nullopt;
  // The outermost layer: surfels within `layer` of the min_surfels-th outermost one (fewer stray
  // surfels standing farther out do not define it, nor count in it).
  std::nth_element(facing.begin(), facing.begin() + (min_surfels - 1), facing.end(),
                   [](const Facing& a, const Facing& b) { return a.along > b.along; });
  const float outer = facing[min_surfels - 1].along;
  double sum = 0, weight = 0, rise = 0, rise_sq = 0, rise_along = 0;
  for (const Facing& f : facing) {
    if (std::abs(f.along - outer) > options.layer) continue;
    sum += f.weight * f.along;
    weight += f.weight;
    rise += f.weight * f.rise;
    rise_sq += f.weight * f.rise * f.rise;
    rise_along += f.weight * f.rise * f.along;
  }
  if (weight <= 0) return std::nullopt;
  double offset = sum / weight;
  // A sliding vertex (a base's rim) has the side's surfels only above it: where the side slopes
  // (a cone's) their mean stands inside the rim, so the layer is extrapolated down to the
  // vertex's height (a weighted line fit of the offset over the height).
  if (sliding) {
    const double mean_rise = rise / weight;
    const double var_rise = rise_sq / weight - mean_rise * mean_rise;
    if (var_rise > kMinRiseSpread * options.radius * options.radius) {
      const double slope = (rise_along / weight - mean_rise * offset) / var_rise;
      offset -= slope * mean_rise;
    }
  }
  return std::clamp(static_cast<float>(offset), -options.max_move, options.max_move);
}

// Each vertex's 1-ring neighbours (with repeats).
std::vector<std::vector<uint32_t>> VertexRings(const TriangleMesh& mesh) {
  std::vector<std::vector<uint32_t>> ring(mesh.vertices.size());
  for (const auto& t : mesh.triangles) {
    for (int k = 0; k < 3; ++k) {
      ring[t[k]].push_back(t[(k + 1) % 3]);
      ring[t[k]].push_back(t[(k + 2) % 3]);
    }
  }
  return ring;
}

// Vertices farther than `reach` from every surfel are pulled towards the nearest (by at most
// max_move), the pulls smoothed over the rings; fixed vertices stay. Returns the pulls.
std::vector<Eigen::Vector3f> PullTowardsSurfels(const TriangleMesh& mesh, const PointIndex3& index,
                                                const std::vector<Eigen::Vector3f>& points,
                                                const SurfelSnapOptions& options,
                                                const std::vector<std::vector<uint32_t>>& ring,
                                                const std::function<bool(size_t)>& is_fixed) {
  const size_t n = mesh.vertices.size();
  std::vector<Eigen::Vector3f> pull(n, Eigen::Vector3f::Zero());
  tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 256),
                    [&](const tbb::blocked_range<size_t>& r) {
                      for (size_t v = r.begin(); v != r.end(); ++v) {
                        const auto [nearest, dist_sq] = index.Nearest(mesh.vertices[v]);
                        const float dist = std::sqrt(dist_sq);
                        if (dist <= options.reach || is_fixed(v)) continue;
                        const float length = std::min(dist - options.reach, options.max_move);
                        pull[v] = length / dist * (points[nearest] - mesh.vertices[v]);
                      }
                    });
  SmoothOverRings(
      ring, is_fixed, [](size_t) { return false; }, options.smooth_passes,
      Eigen::Vector3f::Zero().eval(), &pull);
  return pull;
}

// Per vertex, the signed move along its normal onto the surfels facing its way (snapped = 1),
// or none.
void SnapMoves(const TriangleMesh& mesh, const std::vector<Eigen::Vector3f>& vertex_normals,
               const std::function<bool(size_t)>& is_fixed, const PointIndex3& index,
               const std::vector<Eigen::Vector3f>& points,
               const std::vector<Eigen::Vector3f>& normals, const SurfelSnapOptions& options,
               std::vector<float>* move, std::vector<uint8_t>* snapped) {
  tbb::parallel_for(tbb::blocked_range<size_t>(0, mesh.vertices.size(), 256),
                    [&](const tbb::blocked_range<size_t>& r) {
                      std::vector<Facing> facing;
                      for (size_t v = r.begin(); v != r.end(); ++v) {
                        if (vertex_normals[v].isZero()) continue;
                        const std::optional<float> offset =
                            SnapOffset(mesh.vertices[v], vertex_normals[v], is_fixed(v), index,
                                       points, normals, options, facing);
                        if (!offset) continue;
                        (*move)[v] = *offset;
                        (*snapped)[v] = 1;
                      }
                    });
}

}  // namespace

size_t SnapToSurfels(const std::vector<Eigen::Vector3f>& points,
                     const std::vector<Eigen::Vector3f>& normals, const SurfelSnapOptions& options,
                     TriangleMesh* mesh, const std::vector<uint8_t>& fixed) {
  if (points.empty() || mesh->vertices.empty() || options.radius <= 0 || options.max_move <= 0) {
    return 0;
  }
  std::vector<Eigen::Vector3f> vertex_normals = OutwardVertexNormals(*mesh);
  const std::function<bool(size_t)> is_fixed = [&fixed](size_t v) {
    return v < fixed.size() && fixed[v];
  };
  const bool slide = !options.slide_normal.isZero();
  SlideDirections(fixed, options.slide_normal, &vertex_normals);
  const PointIndex3 index(points);
  const size_t n = mesh->vertices.size();
  // Each vertex's signed move along its normal (0 where too few surfels face its way).
  std::vector<float> move(n, 0.0f);
  std::vector<uint8_t> snapped(n, 0);
  SnapMoves(*mesh, vertex_normals, is_fixed, index, points, normals, options, &move, &snapped);
  // Smooth the moves over each vertex's 1-ring (a vertex that did not snap counts as not moving).
  // Fixed vertices that do not slide (a zero direction) stay. Without a slide they count as not
  // moving (the surface near a fixed base moves less); with one, the rim slides and the inside of
  // the base, which has no say across the slide normal, is left out of its neighbours' means.
  const std::vector<std::vector<uint32_t>> ring = VertexRings(*mesh);
  auto stays = [&](size_t v) { return is_fixed(v) && vertex_normals[v].isZero(); };
  auto left_out = [&](size_t v) { return slide && stays(v); };
  SmoothOverRings(ring, stays, left_out, options.smooth_passes, 0.0f, &move);
  size_t moved = 0;
  for (size_t v = 0; v < n; ++v) {
    mesh->vertices[v] += move[v] * vertex_normals[v];
    moved += snapped[v];
  }
  if (options.reach <= 0) return moved;
  const std::vector<Eigen::Vector3f> pull =
      PullTowardsSurfels(*mesh, index, points, options, ring, is_fixed);
  for (size_t v = 0; v < n; ++v) {
    mesh->vertices[v] += pull[v];
    moved += !snapped[v] && !pull[v].isZero();
  }
  return moved;
}

}  // namespace instascene
