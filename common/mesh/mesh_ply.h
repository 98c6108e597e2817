// common/mesh/mesh_ply.h: triangle meshes as binary little-endian PLY (vertex x y z, optional
// red green blue as uchar, face vertex_indices as a uchar-counted int list), the format every mesh
// the project writes uses (ground-truth meshes of synthetic scenes, completed objects). The reader
// accepts exactly that layout (plus any extra vertex properties, ignored) and rejects anything else
// with an error naming the source; it is bounded by the input size. Stateless, thread-safe.
#pragma once

#include <string>

#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"
#include "common/geometry/triangle_mesh.h"

namespace instascene {

// Encodes vertices, colours (when one per vertex) and triangles.
std::string EncodeMeshPly(const TriangleMesh& mesh);

// Parses a mesh PLY; every index is checked against the vertex count.
absl::StatusOr<TriangleMesh> ParseMeshPly(absl::string_view data, absl::string_view source);

// Reads a mesh PLY file (bounded by max_bytes) / writes one atomically.
absl::StatusOr<TriangleMesh> ReadMeshPly(const std::string& path, size_t max_bytes = 1ull << 31);
absl::Status WriteMeshPly(const std::string& path, const TriangleMesh& mesh);

}  // namespace instascene
