#include "services/objects/convex_hull.h"

#include <cstdio>
#include <limits>
#include <map>

extern "C" {
#include <libqhull_r/qhull_ra.h>
}

#include "absl/strings/str_cat.h"

namespace instascene::objects {
namespace {

// qhull's triangulated facets as a mesh of the input points they use, each facet wound outward.
TriangleMesh HullTriangles(qhT* qh, const std::vector<Eigen::Vector3f>& points) {
  TriangleMesh hull;
  std::map<int, uint32_t> index;  // qhull point id -> hull vertex
  auto vertex_of = [&](vertexT* v) {
    const int id = qh_pointid(qh, v->point);
    auto [it, inserted] = index.emplace(id, static_cast<uint32_t>(hull.vertices.size()));
    if (inserted) hull.vertices.push_back(points[static_cast<size_t>(id)]);
    return it->second;
  };
  facetT* facet;
  FORALLfacets {
    std::array<uint32_t, 3> t{};
    int n = 0;
    vertexT *vertex, **vertexp;
    FOREACHvertex_(facet->vertices) {
      if (n < 3) t[static_cast<size_t>(n)] = vertex_of(vertex);
      ++n;
    }
    if (n != 3) continue;
    const Eigen::Vector3d a = hull.vertices[t[0]].cast<double>();
    const Eigen::Vector3d normal =
        (hull.vertices[t[1]].cast<double>() - a).cross(hull.vertices[t[2]].cast<double>() - a);
    const Eigen::Vector3d facet_normal(facet->normal[0], facet->normal[1], facet->normal[2]);
    if (normal.dot(facet_normal) < 0) std::swap(t[1], t[2]);  // outward
    hull.triangles.push_back(t);
  }
  return hull;
}

}  // namespace

absl::StatusOr<TriangleMesh> ConvexHull(const std::vector<Eigen::Vector3f>& points) {
  if (points.size() < 4)
    return absl::FailedPreconditionError(
        absl::StrCat("a convex hull needs at least 4 points, got ", points.size()));
  std::vector<coordT> coords;
  coords.reserve(3 * points.size());
  for (const Eigen::Vector3f& p : points)
    for (int i = 0; i < 3; ++i) coords.push_back(p[i]);
  FILE* devnull = std::fopen("/dev/null", "w");
  qhT context;
  qhT* qh = &context;
  qh_zero(qh, devnull);
  char options[] = "qhull Qt";  // triangulated output
  const int code = qh_new_qhull(qh, 3, static_cast<int>(points.size()), coords.data(), False,
                                options, nullptr, devnull);
  const TriangleMesh hull = code == 0 ? HullTriangles(qh, points) : TriangleMesh();
  qh_freeqhull(qh, !qh_ALL);
  int curlong = 0, totlong = 0;
  qh_memfreeshort(qh, &curlong, &totlong);
  std::fclose(devnull);
  if (code != 0 || hull.triangles.size() < 4)
    return absl::FailedPreconditionError(absl::StrCat(
        "the ", points.size(), " points span no volume (flat or collinear): no convex hull"));
  return hull;
}

float HullSignedDistance(const TriangleMesh& hull, const Eigen::Vector3f& p) {
  float worst = -std::numeric_limits<float>::infinity();
  for (const auto& t : hull.triangles) {
    const Eigen::Vector3f& a = hull.vertices[t[0]];
    Eigen::Vector3f n = (hull.vertices[t[1]] - a).cross(hull.vertices[t[2]] - a);
    const float len = n.norm();
    if (len == 0) continue;
    worst = std::max(worst, (p - a).dot(n / len));
  }
  return worst;
}

}  // namespace instascene::objects
