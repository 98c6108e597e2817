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
// A rim vertex's outward normal needs this much across the slide normal to extend (a flat
// base's inside has none; its outer ring, where the fused floor rounds into the side, some).
constexpr float kMinRimAcross = 0.05f;
// A rim extends onto a side that narrows upwards: its layer's normals tilt up by at least this
// (6 degrees; the side's radius falls by as much per unit height), and the layer is taken down
// that slope to the rim's height. The normals, not a line fitted to the offsets over height: a
// side's lowest surfels are few and stand within a row or two of one another (the fit gave
// -0.1 to -0.2 on a box's vertical sides, +0.15 to +0.45 on a cone's). A vertical side (a box's,
// a cylinder's) stays with the clamps, which hold it to its surfels exactly, and the
// move along a corner's diagonal would stand out past one of its faces; a side that widens upwards
// (a bowl's foot, a torus's underside) extrapolated down does not reach the support where it does.
constexpr float kMinRimNarrowing = 0.1f;
// And the facing surfels' offsets fall with height by at least this share of what their normals
// say (on a cone the two agree; at a bottle's foot a few tilted surfels did not).
constexpr float kMinSlopeAgreement = 0.5f;

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
  float tilt;  // the surfel's normal, turned to face the vertex's way, along the slide normal
};

// A weighted line fit of surfels' offsets (along) over their heights (rise).
struct RiseLine {
  double weight = 0, rise = 0, along = 0, rise_sq = 0, rise_along = 0;
  void Add(const Facing& f) {
    along += f.weight * f.along;
    weight += f.weight;
    rise += f.weight * f.rise;
    rise_sq += f.weight * f.rise * f.rise;
    rise_along += f.weight * f.rise * f.along;
  }
  // The slope, where the heights spread enough to fit one (their variance above kMinRiseSpread
  // times the neighbourhood's radius squared).
  std::optional<double> Slope(float radius) const {
    if (weight <= 0) return std::nullopt;
    const double mean_rise = rise / weight;
    const double var_rise = rise_sq / weight - mean_rise * mean_rise;
    if (!(var_rise > kMinRiseSpread * radius * radius)) return std::nullopt;
    return (rise_along / weight - mean_rise * along / weight) / var_rise;
  }
};

// The outermost layer of the surfels around `p` that face `nv`'s way: its offset along `nv`, its
// height along the slide normal and its normals' tilt along it.
struct LayerFit {
  float offset = 0.0f;  // extrapolated to the vertex's height when sliding
  // The layer's mean normal (turned to face the vertex's way): its part along the slide normal
  // over its part across it. A side whose width falls by t per unit height has tilt t.
  float tilt = 0.0f;
  float mean_offset = 0.0f, mean_rise = 0.0f;  // the layer's, before any extrapolation
};

// The surfels around the vertex at `p` that face its normal `nv`'s way (either sign), weighted by
// their distance across the normal.
void GatherFacing(const Eigen::Vector3f& p, const Eigen::Vector3f& nv, const PointIndex3& index,
                  const std::vector<Eigen::Vector3f>& points,
                  const std::vector<Eigen::Vector3f>& normals, const SurfelSnapOptions& options,
                  std::vector<Facing>& facing) {
  const float tangential_var = 0.25f * options.radius * options.radius;
  facing.clear();
  for (uint32_t i : index.WithinRadius(p, options.radius)) {
    const float cos = normals[i].dot(nv);
    if (std::abs(cos) < options.min_cos) continue;
    const Eigen::Vector3f d = points[i] - p;
    const float along = d.dot(nv);
    const float tangential_sq = std::max(0.0f, d.squaredNorm() - along * along);
    const float tilt = std::copysign(1.0f, cos) * normals[i].dot(options.slide_normal);
    facing.push_back({along, std::exp(-0.5f * tangential_sq / tangential_var),
                      d.dot(options.slide_normal), tilt});
  }
}

// The layer around the vertex at `p` (normal `nv`); nullopt where fewer than min_surfels face
// its way. `sliding`: extrapolated down (or up) to the vertex's height along the slide normal.
std::optional<LayerFit> FitLayer(const Eigen::Vector3f& p, const Eigen::Vector3f& nv, bool sliding,
                                 const PointIndex3& index,
                                 const std::vector<Eigen::Vector3f>& points,
                                 const std::vector<Eigen::Vector3f>& normals,
                                 const SurfelSnapOptions& options, std::vector<Facing>& facing) {
  const int min_surfels = std::max(1, options.min_surfels);
  GatherFacing(p, nv, index, points, normals, options, facing);
  if (static_cast<int>(facing.size()) < min_surfels) return std::nullopt;
  // The outermost layer: surfels within `layer` of the min_surfels-th outermost one (fewer stray
  // surfels standing farther out do not define it, nor count in it).
  std::nth_element(facing.begin(), facing.begin() + (min_surfels - 1), facing.end(),
                   [](const Facing& a, const Facing& b) { return a.along > b.along; });
  const float outer = facing[min_surfels - 1].along;
  RiseLine line;  // over the layer
  double tilt = 0, facing_cos = 0;
  for (const Facing& f : facing) {
    if (std::abs(f.along - outer) > options.layer) continue;
    tilt += f.weight * f.tilt;
    facing_cos += f.weight * std::sqrt(std::max(0.0f, 1.0f - f.tilt * f.tilt));
    line.Add(f);
  }
  if (line.weight <= 0) return std::nullopt;
  LayerFit fit;
  fit.tilt = static_cast<float>(tilt / std::max(facing_cos, 1e-9));
  fit.mean_offset = static_cast<float>(line.along / line.weight);
  fit.mean_rise = static_cast<float>(line.rise / line.weight);
  double offset = line.along / line.weight;
  // A sliding vertex (a base's rim) has the side's surfels only above it: where the side slopes
  // (a cone's) their mean stands inside the rim, so the layer is extrapolated down to the
  // vertex's height (a weighted line fit of the offset over the height).
  if (sliding) {
    if (const std::optional<double> slope = line.Slope(options.radius)) {
      offset -= *slope * (line.rise / line.weight);
    }
  }
  fit.offset = static_cast<float>(offset);
  return fit;
}

// The slope of the facing surfels' offsets over their heights (a weighted line fit), where their
// heights spread enough to fit one.
std::optional<float> SideSlope(const std::vector<Facing>& facing, float radius) {
  RiseLine line;
  for (const Facing& f : facing) line.Add(f);
  const std::optional<double> slope = line.Slope(radius);
  if (!slope) return std::nullopt;
  return static_cast<float>(*slope);
}

// ExtendRimToSide's move of the rim vertex at `p` along `nv` (across the slide normal): onto its
// side's foot, or 0.
float RimMove(const Eigen::Vector3f& p, const Eigen::Vector3f& nv, const PointIndex3& index,
              const std::vector<Eigen::Vector3f>& points,
              const std::vector<Eigen::Vector3f>& normals, const SurfelSnapOptions& options,
              std::vector<Facing>& facing) {
  const std::optional<LayerFit> fit =
      FitLayer(p, nv, /*sliding=*/false, index, points, normals, options, facing);
  if (!fit || !(fit->tilt >= kMinRimNarrowing)) return 0.0f;
  // The surfels' offsets fall with height as their normals say (a few tilted surfels at a
  // vertical side's foot, added by the support's walls, do not make it a cone's).
  const std::optional<float> slope = SideSlope(facing, options.radius);
  if (!slope || !(*slope <= -kMinSlopeAgreement * fit->tilt)) return 0.0f;
  // The layer's offset taken down its normals' slope to the vertex's height. A vertex more than
  // two layers' widths inside the layer itself, or whose foot stands farther than max_move, is
  // not at its side's foot (a floor vertex whose layer is a side's surfels 4-14 mm away, a dent
  // 3 mm inside a bottle's foot).
  if (fit->mean_offset > 2 * options.layer) return 0.0f;
  const float offset = fit->mean_offset + fit->tilt * fit->mean_rise;
  return offset > 0 && offset <= options.max_move ? offset : 0.0f;
}

// The signed move of the vertex at `p` along `nv` onto the outermost layer of the surfels that
// face its way; nullopt where fewer than min_surfels do.
std::optional<float> SnapOffset(const Eigen::Vector3f& p, const Eigen::Vector3f& nv, bool sliding,
                                const PointIndex3& index,
                                const std::vector<Eigen::Vector3f>& points,
                                const std::vector<Eigen::Vector3f>& normals,
                                const SurfelSnapOptions& options, std::vector<Facing>& facing) {
  const std::optional<LayerFit> fit =
      FitLayer(p, nv, sliding, index, points, normals, options, facing);
  if (!fit) return std::nullopt;
  return std::clamp(fit->offset, -options.max_move, options.max_move);
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

size_t ExtendRimToSide(const std::vector<Eigen::Vector3f>& points,
                       const std::vector<Eigen::Vector3f>& normals,
                       const SurfelSnapOptions& options, TriangleMesh* mesh,
                       const std::vector<uint8_t>& rim) {
  const Eigen::Vector3f& up = options.slide_normal;
  if (points.empty() || rim.size() != mesh->vertices.size() || options.radius <= 0 ||
      options.max_move <= 0 || up.isZero()) {
    return 0;
  }
  std::vector<Eigen::Vector3f> direction = OutwardVertexNormals(*mesh);
  for (size_t v = 0; v < direction.size(); ++v) {
    const Eigen::Vector3f across = direction[v] - direction[v].dot(up) * up;
    direction[v] = rim[v] && across.norm() >= kMinRimAcross ? Eigen::Vector3f(across.normalized())
                                                            : Eigen::Vector3f::Zero();
  }
  const PointIndex3 index(points);
  const size_t n = mesh->vertices.size();
  std::vector<float> move(n, 0.0f);
  tbb::parallel_for(
      tbb::blocked_range<size_t>(0, n, 256), [&](const tbb::blocked_range<size_t>& r) {
        std::vector<Facing> facing;
        for (size_t v = r.begin(); v != r.end(); ++v) {
          if (direction[v].isZero()) continue;
          move[v] =
              RimMove(mesh->vertices[v], direction[v], index, points, normals, options, facing);
        }
      });
  // Not smoothed over the mesh: the ring's vertices stand at different heights of a slope, each
  // move is to its own height's point of the side, and the fit already averages the side's
  // surfels around it.
  size_t moved = 0;
  for (size_t v = 0; v < n; ++v) {
    mesh->vertices[v] += move[v] * direction[v];
    moved += move[v] > 0;
  }
  return moved;
}

}  // namespace instascene
