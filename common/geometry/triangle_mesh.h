// common/geometry/triangle_mesh.h: an indexed triangle mesh with optional per-vertex UVs.
//
// Used for procedural ground-truth geometry (synthetic scenes), completion metrics, Embree ray
// casting (common/mesh) and mesh export. Value type; thread-safe for concurrent reads.
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "common/geometry/rigid.h"

namespace instascene {

struct TriangleMesh {
  std::vector<Eigen::Vector3f> vertices;
  std::vector<Eigen::Vector2f> uvs;     // empty, or one per vertex
  std::vector<Eigen::Vector3f> colors;  // empty, or one linear RGB in [0, 1] per vertex
  std::vector<std::array<uint32_t, 3>> triangles;

  float TriangleArea(size_t t) const {
    const auto& tri = triangles[t];
    return 0.5f *
           (vertices[tri[1]] - vertices[tri[0]]).cross(vertices[tri[2]] - vertices[tri[0]]).norm();
  }
  float SurfaceArea() const {
    double area = 0;
    for (size_t t = 0; t < triangles.size(); ++t) area += TriangleArea(t);
    return static_cast<float>(area);
  }
  // Applies target_from_mesh to every vertex.
  void Transform(const Rigid3d& target_from_mesh, float scale = 1.0f) {
    for (Eigen::Vector3f& v : vertices) {
      v = (target_from_mesh * (scale * v).cast<double>()).cast<float>();
    }
  }
  // Appends another mesh (indices shifted).
  void Append(const TriangleMesh& other) {
    const uint32_t base = static_cast<uint32_t>(vertices.size());
    const bool keep_uv = uvs.size() == vertices.size() && other.uvs.size() == other.vertices.size();
    const bool keep_colors =
        colors.size() == vertices.size() && other.colors.size() == other.vertices.size();
    vertices.insert(vertices.end(), other.vertices.begin(), other.vertices.end());
    if (keep_uv)
      uvs.insert(uvs.end(), other.uvs.begin(), other.uvs.end());
    else
      uvs.clear();
    if (keep_colors)
      colors.insert(colors.end(), other.colors.begin(), other.colors.end());
    else
      colors.clear();
    for (const auto& t : other.triangles)
      triangles.push_back({t[0] + base, t[1] + base, t[2] + base});
  }
  Eigen::AlignedBox3f Bounds() const {
    Eigen::AlignedBox3f box;
    for (const Eigen::Vector3f& v : vertices) box.extend(v);
    return box;
  }
};

}  // namespace instascene
