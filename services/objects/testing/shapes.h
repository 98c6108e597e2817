// services/objects/testing/shapes.h: closed test meshes with known geometry for the objects tests
// and benchmarks: surfaces of revolution, and a cup (a hollow cylinder with a bottom).
#pragma once

#include <cmath>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "common/geometry/triangle_mesh.h"
#include "services/objects/mass_properties.h"

namespace instascene::objects::testing {

// A closed surface of revolution about z of the profile (r, z), whose ends lie on the axis;
// outward-oriented.
inline TriangleMesh Revolve(const std::vector<Eigen::Vector2f>& profile, int segments) {
  TriangleMesh m;
  std::vector<std::vector<uint32_t>> rings;
  for (const Eigen::Vector2f& p : profile) {
    std::vector<uint32_t> ring;
    const int n = p.x() == 0 ? 1 : segments;
    for (int j = 0; j < n; ++j) {
      const float a = 2.0f * static_cast<float>(M_PI) * static_cast<float>(j) / segments;
      ring.push_back(static_cast<uint32_t>(m.vertices.size()));
      m.vertices.emplace_back(p.x() * std::cos(a), p.x() * std::sin(a), p.y());
    }
    rings.push_back(ring);
  }
  for (size_t i = 0; i + 1 < rings.size(); ++i) {
    const auto &a = rings[i], &b = rings[i + 1];
    for (int j = 0; j < segments; ++j) {
      const int k = (j + 1) % segments;
      auto at = [](const std::vector<uint32_t>& r, int x) { return r[r.size() == 1 ? 0 : x]; };
      if (a.size() > 1) m.triangles.push_back({at(a, j), at(a, k), at(b, k)});
      if (b.size() > 1) m.triangles.push_back({at(a, j), at(b, k), at(b, j)});
    }
  }
  if (MeshMassProperties(m).volume < 0)
    for (auto& t : m.triangles) std::swap(t[1], t[2]);
  return m;
}

// A cup: outer radius 1, height 2 (z in [-1, 1]), wall 0.2, bottom 0.2; `rings` extra profile
// points per side make it denser (for benchmarks at the size of real meshes).
inline TriangleMesh Cup(int segments = 48, int rings = 0) {
  const std::vector<Eigen::Vector2f> corners = {{0, -1},   {1, -1},       {1, 1},
                                                {0.8f, 1}, {0.8f, -0.8f}, {0, -0.8f}};
  std::vector<Eigen::Vector2f> profile;
  for (size_t i = 0; i + 1 < corners.size(); ++i)
    for (int s = 0; s <= rings; ++s)
      profile.push_back(corners[i] +
                        (corners[i + 1] - corners[i]) * (static_cast<float>(s) / (rings + 1)));
  profile.push_back(corners.back());
  return Revolve(profile, segments);
}

}  // namespace instascene::objects::testing
