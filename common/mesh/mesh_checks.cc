#include "common/mesh/mesh_checks.h"

#include <algorithm>
#include <cstdint>
#include <vector>

namespace instascene {

bool IsClosedManifold(const TriangleMesh& mesh) {
  if (mesh.triangles.empty()) return false;
  std::vector<uint64_t> edges;
  edges.reserve(3 * mesh.triangles.size());
  for (const auto& t : mesh.triangles) {
    for (int k = 0; k < 3; ++k) {
      const uint64_t a = t[k], b = t[(k + 1) % 3];
      if (a == b) return false;  // degenerate triangle
      edges.push_back((std::min(a, b) << 32) | std::max(a, b));
    }
  }
  std::sort(edges.begin(), edges.end());
  for (size_t i = 0; i < edges.size();) {
    size_t j = i;
    while (j < edges.size() && edges[j] == edges[i]) ++j;
    if (j - i != 2) return false;
    i = j;
  }
  return true;
}

}  // namespace instascene
