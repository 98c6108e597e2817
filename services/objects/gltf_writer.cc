#include "services/objects/gltf_writer.h"

#include <cstring>

#include <draco/compression/decode.h>
#include <draco/compression/encode.h>
#include <draco/mesh/triangle_soup_mesh_builder.h>
#include <nlohmann/json.hpp>

#include "absl/strings/str_cat.h"
#include "common/core/status.h"

namespace instascene::objects {
namespace {

void AppendU32(std::string* out, uint32_t v) {
  char b[4];
  std::memcpy(b, &v, 4);  // little-endian host (x86-64, aarch64)
  out->append(b, 4);
}

// The mesh as a Draco mesh: positions (attribute id in *pos) and, where every vertex has one,
// 8-bit colours (*col, else -1).
absl::StatusOr<std::unique_ptr<draco::Mesh>> BuildDracoMesh(const TriangleMesh& mesh, int* pos,
                                                            int* col) {
  const bool colored = mesh.colors.size() == mesh.vertices.size();
  draco::TriangleSoupMeshBuilder builder;
  builder.Start(static_cast<int>(mesh.triangles.size()));
  *pos = builder.AddAttribute(draco::GeometryAttribute::POSITION, 3, draco::DT_FLOAT32);
  *col = colored ? builder.AddAttribute(draco::GeometryAttribute::COLOR, 3, draco::DT_UINT8, true)
                 : -1;
  for (size_t f = 0; f < mesh.triangles.size(); ++f) {
    const auto& t = mesh.triangles[f];
    for (uint32_t v : t)
      if (v >= mesh.vertices.size()) return absl::InvalidArgumentError("glb: bad vertex index");
    builder.SetAttributeValuesForFace(*pos, draco::FaceIndex(static_cast<uint32_t>(f)),
                                      mesh.vertices[t[0]].data(), mesh.vertices[t[1]].data(),
                                      mesh.vertices[t[2]].data());
    if (colored) {
      uint8_t c[3][3];
      for (int k = 0; k < 3; ++k)
        for (int ch = 0; ch < 3; ++ch)
          c[k][ch] = static_cast<uint8_t>(
              std::clamp(mesh.colors[t[static_cast<size_t>(k)]][ch], 0.0f, 1.0f) * 255.0f + 0.5f);
      builder.SetAttributeValuesForFace(*col, draco::FaceIndex(static_cast<uint32_t>(f)), c[0],
                                        c[1], c[2]);
    }
  }
  std::unique_ptr<draco::Mesh> draco_mesh = builder.Finalize();
  if (!draco_mesh) return absl::InternalError("Draco: mesh building failed");
  return draco_mesh;
}

// The glTF document of one node, one mesh, one vertex-colour material and one Draco-compressed
// primitive whose accessors describe the decoded data (`box`: its positions' bounds).
nlohmann::json GltfDocument(const GlbResult& out, const draco::Mesh& draco_mesh, int pos, int col,
                            const Eigen::AlignedBox3f& box, size_t bin_bytes,
                            const std::string& name) {
  using nlohmann::json;
  json attributes = {{"POSITION", 0}};
  json draco_attributes = {{"POSITION", draco_mesh.attribute(pos)->unique_id()}};
  json accessors = json::array();
  accessors.push_back({{"componentType", 5126},
                       {"count", out.vertices},
                       {"type", "VEC3"},
                       {"min", {box.min().x(), box.min().y(), box.min().z()}},
                       {"max", {box.max().x(), box.max().y(), box.max().z()}}});
  if (col >= 0) {
    attributes["COLOR_0"] = 1;
    draco_attributes["COLOR_0"] = draco_mesh.attribute(col)->unique_id();
    accessors.push_back(
        {{"componentType", 5121}, {"normalized", true}, {"count", out.vertices}, {"type", "VEC3"}});
  }
  const int indices = static_cast<int>(accessors.size());
  accessors.push_back({{"componentType", out.vertices > 65535 ? 5125 : 5123},
                       {"count", 3 * out.triangles},
                       {"type", "SCALAR"}});
  return {
      {"asset", {{"version", "2.0"}, {"generator", "InstaScene export"}}},
      {"extensionsUsed", {"KHR_draco_mesh_compression"}},
      {"extensionsRequired", {"KHR_draco_mesh_compression"}},
      {"scene", 0},
      {"scenes", {{{"nodes", {0}}}}},
      {"nodes", {{{"mesh", 0}, {"name", name}}}},
      {"materials",
       {{{"name", "vertex_colour"},
         {"pbrMetallicRoughness",
          {{"baseColorFactor", {1, 1, 1, 1}}, {"metallicFactor", 0}, {"roughnessFactor", 1}}}}}},
      {"meshes",
       {{{"name", name},
         {"primitives",
          {{{"attributes", attributes},
            {"indices", indices},
            {"material", 0},
            {"mode", 4},
            {"extensions",
             {{"KHR_draco_mesh_compression",
               {{"bufferView", 0}, {"attributes", draco_attributes}}}}}}}}}}},
      {"accessors", accessors},
      {"bufferViews", {{{"buffer", 0}, {"byteOffset", 0}, {"byteLength", out.draco.size()}}}},
      {"buffers", {{{"byteLength", bin_bytes}}}},
  };
}

// The GLB container: header, the JSON chunk (space-padded) and the BIN chunk (zero-padded).
std::string PackGlb(std::string text, std::string bin) {
  while (text.size() % 4 != 0) text.push_back(' ');
  while (bin.size() % 4 != 0) bin.push_back('\0');
  const uint32_t total =
      12 + 8 + static_cast<uint32_t>(text.size()) + 8 + static_cast<uint32_t>(bin.size());
  std::string bytes;
  bytes.reserve(total);
  bytes.append("glTF", 4);
  AppendU32(&bytes, 2);
  AppendU32(&bytes, total);
  AppendU32(&bytes, static_cast<uint32_t>(text.size()));
  bytes.append("JSON", 4);
  bytes += text;
  AppendU32(&bytes, static_cast<uint32_t>(bin.size()));
  bytes.append("BIN\0", 4);
  bytes += bin;
  return bytes;
}

}  // namespace

absl::StatusOr<TriangleMesh> DecodeDraco(const std::string& bytes) {
  draco::DecoderBuffer buffer;
  buffer.Init(bytes.data(), bytes.size());
  draco::Decoder decoder;
  auto decoded = decoder.DecodeMeshFromBuffer(&buffer);
  if (!decoded.ok())
    return absl::DataLossError(absl::StrCat("Draco: ", decoded.status().error_msg_string()));
  const draco::Mesh& m = *decoded.value();
  TriangleMesh out;
  const draco::PointAttribute* pos = m.GetNamedAttribute(draco::GeometryAttribute::POSITION);
  const draco::PointAttribute* col = m.GetNamedAttribute(draco::GeometryAttribute::COLOR);
  if (pos == nullptr) return absl::DataLossError("Draco: no positions");
  for (draco::PointIndex i(0); i < m.num_points(); ++i) {
    float p[3];
    pos->ConvertValue<float, 3>(pos->mapped_index(i), p);
    out.vertices.emplace_back(p[0], p[1], p[2]);
    if (col != nullptr) {
      float c[3];
      col->ConvertValue<float, 3>(col->mapped_index(i), c);
      out.colors.emplace_back(c[0], c[1], c[2]);
    }
  }
  for (draco::FaceIndex f(0); f < m.num_faces(); ++f) {
    const auto& face = m.face(f);
    out.triangles.push_back({face[0].value(), face[1].value(), face[2].value()});
  }
  return out;
}

absl::StatusOr<GlbResult> EncodeDracoGlb(const TriangleMesh& mesh, const GlbOptions& options) {
  if (mesh.triangles.empty()) return absl::InvalidArgumentError("glb: the mesh has no triangles");
  int pos = -1, col = -1;
  ASSIGN_OR_RETURN(std::unique_ptr<draco::Mesh> draco_mesh, BuildDracoMesh(mesh, &pos, &col));
  draco::Encoder encoder;
  encoder.SetAttributeQuantization(draco::GeometryAttribute::POSITION, options.position_bits);
  encoder.SetSpeedOptions(5, 5);
  draco::EncoderBuffer buffer;
  const draco::Status status = encoder.EncodeMeshToBuffer(*draco_mesh, &buffer);
  if (!status.ok()) return absl::InternalError(absl::StrCat("Draco: ", status.error_msg_string()));
  GlbResult out;
  out.draco.assign(buffer.data(), buffer.size());
  // What a reader gets back: the accessors describe the decoded data.
  ASSIGN_OR_RETURN(TriangleMesh decoded, DecodeDraco(out.draco));
  out.vertices = decoded.vertices.size();
  out.triangles = decoded.triangles.size();
  Eigen::AlignedBox3f box;
  for (const Eigen::Vector3f& v : decoded.vertices) box.extend(v);
  const size_t bin_bytes = (out.draco.size() + 3) / 4 * 4;
  const nlohmann::json gltf =
      GltfDocument(out, *draco_mesh, pos, col, box, bin_bytes, options.name);
  out.bytes = PackGlb(gltf.dump(), out.draco);
  return out;
}

}  // namespace instascene::objects
