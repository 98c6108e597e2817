#include "common/mesh/mesh_ply.h"

#include <algorithm>
#include <cmath>
#include <cstring>

#include "absl/strings/str_cat.h"
#include "common/core/file_io.h"
#include "common/core/status.h"
#include "common/splat/ply.h"

namespace instascene {
namespace {

uint8_t ToByte(float v) {
  return static_cast<uint8_t>(std::lround(std::clamp(v, 0.0f, 1.0f) * 255.0f));
}

}  // namespace

std::string EncodeMeshPly(const TriangleMesh& mesh) {
  const bool colored = !mesh.colors.empty() && mesh.colors.size() == mesh.vertices.size();
  std::string out =
      absl::StrCat("ply\nformat binary_little_endian 1.0\nelement vertex ", mesh.vertices.size(),
                   "\nproperty float x\nproperty float y\nproperty float z\n",
                   colored ? "property uchar red\nproperty uchar green\nproperty uchar blue\n" : "",
                   "element face ", mesh.triangles.size(),
                   "\nproperty list uchar int vertex_indices\nend_header\n");
  out.reserve(out.size() + mesh.vertices.size() * 15 + mesh.triangles.size() * 13);
  for (size_t v = 0; v < mesh.vertices.size(); ++v) {
    out.append(reinterpret_cast<const char*>(mesh.vertices[v].data()), 12);
    if (colored) {
      for (int c = 0; c < 3; ++c) out.push_back(static_cast<char>(ToByte(mesh.colors[v][c])));
    }
  }
  for (const auto& t : mesh.triangles) {
    out.push_back(3);
    for (uint32_t i : t) {
      const int32_t index = static_cast<int32_t>(i);
      out.append(reinterpret_cast<const char*>(&index), 4);
    }
  }
  return out;
}

namespace {

// Binary little-endian, 'vertex' (no list properties) then 'face' (one 'list uchar int
// vertex_indices'): what this reader (and our writer) handles.
absl::Status CheckMeshHeader(const PlyHeader& header, absl::string_view source) {
  auto unsupported = [&](absl::string_view what) {
    return absl::InvalidArgumentError(absl::StrCat(source, ": unsupported mesh PLY: ", what));
  };
  if (header.format != PlyFormat::kBinaryLittleEndian)
    return unsupported("not binary little-endian");
  if (header.elements.size() != 2 || header.elements[0].name != "vertex" ||
      header.elements[1].name != "face") {
    return unsupported("expected elements 'vertex' then 'face'");
  }
  const PlyElement& faces = header.elements[1];
  if (faces.properties.size() != 1 || !faces.properties[0].is_list ||
      faces.properties[0].count_type != ScalarType::kUint8 ||
      (faces.properties[0].type != ScalarType::kInt32 &&
       faces.properties[0].type != ScalarType::kUint32)) {
    return unsupported("face must hold one 'list uchar int vertex_indices'");
  }
  for (const PlyProperty& p : header.elements[0].properties) {
    if (p.is_list) return unsupported("list property on vertices");
  }
  return absl::OkStatus();
}

// The triangles: after the vertex block, 13-byte records (count 3, three int32 indices), each
// index within [0, vertices).
absl::Status ReadTriangles(absl::string_view data, const PlyHeader& header, int64_t vertices,
                           absl::string_view source, TriangleMesh* mesh) {
  const PlyElement& faces = header.elements[1];
  // Faces follow the vertex block: fixed-size vertex records (no lists on vertices).
  size_t vertex_bytes = 0;
  for (const PlyProperty& p : header.elements[0].properties) vertex_bytes += ScalarTypeSize(p.type);
  size_t offset = header.data_offset + vertex_bytes * static_cast<size_t>(vertices);
  constexpr size_t kFaceBytes = 13;
  if (faces.count < 0 || data.size() < offset ||
      (data.size() - offset) / kFaceBytes < static_cast<size_t>(faces.count)) {
    return absl::InvalidArgumentError(
        absl::StrCat(source, ": truncated: ", faces.count, " faces do not fit"));
  }
  mesh->triangles.resize(faces.count);
  for (int64_t f = 0; f < faces.count; ++f, offset += kFaceBytes) {
    if (static_cast<uint8_t>(data[offset]) != 3) {
      return absl::InvalidArgumentError(absl::StrCat(source, ": face ", f, " is not a triangle"));
    }
    for (int k = 0; k < 3; ++k) {
      int32_t index;
      std::memcpy(&index, data.data() + offset + 1 + 4 * k, 4);
      if (index < 0 || index >= vertices) {
        return absl::InvalidArgumentError(
            absl::StrCat(source, ": face ", f, " index ", index, " outside [0, ", vertices, ")"));
      }
      mesh->triangles[f][k] = static_cast<uint32_t>(index);
    }
  }
  return absl::OkStatus();
}

}  // namespace

absl::StatusOr<TriangleMesh> ParseMeshPly(absl::string_view data, absl::string_view source) {
  ASSIGN_OR_RETURN(PlyHeader header, ParsePlyHeader(data, source));
  RETURN_IF_ERROR(CheckMeshHeader(header, source));
  ASSIGN_OR_RETURN(PlyColumns vertices, ReadPlyElement(data, header, "vertex", source));
  const int x = vertices.Find("x"), y = vertices.Find("y"), z = vertices.Find("z");
  if (x < 0 || y < 0 || z < 0)
    return absl::InvalidArgumentError(
        absl::StrCat(source, ": unsupported mesh PLY: vertex lacks x, y or z"));
  const int r = vertices.Find("red"), g = vertices.Find("green"), b = vertices.Find("blue");
  TriangleMesh mesh;
  mesh.vertices.resize(vertices.count);
  for (int64_t i = 0; i < vertices.count; ++i) {
    mesh.vertices[i] = {vertices.columns[x][i], vertices.columns[y][i], vertices.columns[z][i]};
    if (!mesh.vertices[i].allFinite()) {
      return absl::InvalidArgumentError(absl::StrCat(source, ": vertex ", i, " is not finite"));
    }
  }
  if (r >= 0 && g >= 0 && b >= 0) {
    mesh.colors.resize(vertices.count);
    for (int64_t i = 0; i < vertices.count; ++i) {
      mesh.colors[i] =
          Eigen::Vector3f(vertices.columns[r][i], vertices.columns[g][i], vertices.columns[b][i]) /
          255.0f;
    }
  }
  RETURN_IF_ERROR(ReadTriangles(data, header, vertices.count, source, &mesh));
  return mesh;
}

absl::StatusOr<TriangleMesh> ReadMeshPly(const std::string& path, size_t max_bytes) {
  ASSIGN_OR_RETURN(std::string data, ReadFileBounded(path, max_bytes));
  return ParseMeshPly(data, path);
}

absl::Status WriteMeshPly(const std::string& path, const TriangleMesh& mesh) {
  return WriteFileAtomically(path, EncodeMeshPly(mesh));
}

}  // namespace instascene
