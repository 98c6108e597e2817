// common/mesh/mesh_checks.h: topology checks of triangle meshes. Pure functions, thread-safe.
#pragma once

#include "common/geometry/triangle_mesh.h"

namespace instascene {

// True when the mesh is non-empty and every undirected edge is shared by exactly two triangles
// (closed, edge-manifold: "watertight" in Open3D's and trimesh's sense).
bool IsClosedManifold(const TriangleMesh& mesh);

}  // namespace instascene
