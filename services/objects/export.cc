#include "services/objects/export.h"

#include <algorithm>
#include <filesystem>
#include <random>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "common/core/file_io.h"
#include "common/core/status.h"
#include "common/mesh/mesh_ply.h"
#include "common/store/digest.h"
#include "services/objects/convex_hull.h"
#include "services/objects/gltf_writer.h"
#include "services/objects/mass_properties.h"
#include "services/objects/robot_formats.h"

namespace instascene::objects {
namespace {
namespace fs = std::filesystem;
using nlohmann::json;

json Vec(const Eigen::Vector3d& v) { return {v.x(), v.y(), v.z()}; }

// world_from_object from the completion manifest: 3 rows of [R | t].
absl::StatusOr<Eigen::Isometry3d> ParsePose(const json& m, const std::string& source) {
  const json& rows = m.value("world_from_object", json());
  if (!rows.is_array() || rows.size() != 3)
    return absl::DataLossError(absl::StrCat(source, ": world_from_object must be 3 rows of 4"));
  Eigen::Matrix<double, 3, 4> p;
  for (int r = 0; r < 3; ++r) {
    if (!rows[r].is_array() || rows[r].size() != 4)
      return absl::DataLossError(
          absl::StrCat(source, ": world_from_object row ", r, " is not 4 numbers"));
    for (int c = 0; c < 4; ++c) {
      if (!rows[r][c].is_number())
        return absl::DataLossError(absl::StrCat(source, ": world_from_object is not numeric"));
      p(r, c) = rows[r][c].get<double>();
    }
  }
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.linear() = p.leftCols<3>();
  pose.translation() = p.col(3);
  if ((pose.linear().transpose() * pose.linear() - Eigen::Matrix3d::Identity()).norm() > 1e-3)
    return absl::DataLossError(absl::StrCat(source, ": world_from_object is not a rotation"));
  return pose;
}

// Binary little-endian PLY of points with normals.
std::string PointsPly(const std::vector<Eigen::Vector3f>& p,
                      const std::vector<Eigen::Vector3f>& n) {
  std::string out = absl::StrCat(
      "ply\nformat binary_little_endian 1.0\ncomment InstaScene surface samples (metres when "
      "scaled)\nelement vertex ",
      p.size(),
      "\nproperty float x\nproperty float y\nproperty float z\nproperty float nx\nproperty float "
      "ny\nproperty float nz\nend_header\n");
  for (size_t i = 0; i < p.size(); ++i) {
    out.append(reinterpret_cast<const char*>(p[i].data()), 12);
    out.append(reinterpret_cast<const char*>(n[i].data()), 12);
  }
  return out;
}

}  // namespace

absl::Status ExportOptions::Validate() const {
  if (!(density > 0 && density < 1e5))
    return absl::InvalidArgumentError("density must be in (0, 1e5) kg/m³");
  if (surface_points < 1 || surface_points > 1000000)
    return absl::InvalidArgumentError("surface_points must be in [1, 1000000]");
  return decomposition.Validate();
}

absl::StatusOr<json> ExportObject(const std::string& object_dir, const MetricScale& scale,
                                  const ExportOptions& options, const std::string& out_dir) {
  RETURN_IF_ERROR(options.Validate());
  const std::string manifest_path = (fs::path(object_dir) / "manifest.json").string();
  ASSIGN_OR_RETURN(std::string manifest_text, ReadFileBounded(manifest_path, 64 << 20));
  const json in = json::parse(manifest_text, nullptr, false);
  if (in.is_discarded() || !in.is_object())
    return absl::DataLossError(absl::StrCat(manifest_path, ": not a JSON object"));
  ASSIGN_OR_RETURN(Eigen::Isometry3d world_from_object, ParsePose(in, manifest_path));
  ASSIGN_OR_RETURN(TriangleMesh world_mesh,
                   ReadMeshPly((fs::path(object_dir) / "mesh.ply").string()));
  if (world_mesh.triangles.empty())
    return absl::DataLossError(absl::StrCat(object_dir, "/mesh.ply: no triangles"));
  const double s = scale.meters_per_unit.value_or(1.0);
  if (!(s > 0)) return absl::InvalidArgumentError("meters_per_unit must be positive");
  const uint32_t id = in.value("id", 0u);
  const std::string name = absl::StrCat("object_", id);

  // The object frame, in metres.
  TriangleMesh mesh = world_mesh;
  const Eigen::Matrix3d r = world_from_object.linear();
  const Eigen::Vector3d t = world_from_object.translation();
  for (Eigen::Vector3f& v : mesh.vertices)
    v = (s * (r.transpose() * (v.cast<double>() - t))).cast<float>();
  // Faces with two corners at one position (marching cubes makes a few) have no area; Draco drops
  // them, so every artefact drops them and all agree on the triangle count.
  const size_t input_triangles = mesh.triangles.size();
  mesh.triangles.erase(std::remove_if(mesh.triangles.begin(), mesh.triangles.end(),
                                      [&](const std::array<uint32_t, 3>& f) {
                                        const auto& v = mesh.vertices;
                                        return v[f[0]] == v[f[1]] || v[f[1]] == v[f[2]] ||
                                               v[f[0]] == v[f[2]];
                                      }),
                       mesh.triangles.end());
  if (mesh.triangles.empty())
    return absl::DataLossError(absl::StrCat(object_dir, "/mesh.ply: only degenerate triangles"));
  Eigen::AlignedBox3f box;
  for (const Eigen::Vector3f& v : mesh.vertices) box.extend(v);

  std::error_code ec;
  fs::create_directories(fs::path(out_dir) / "collision", ec);
  if (ec) return absl::UnavailableError(absl::StrCat(out_dir, ": ", ec.message()));
  json artefacts = json::object();
  auto write = [&](const std::string& relative, const std::string& bytes) -> absl::Status {
    RETURN_IF_ERROR(WriteFileAtomically((fs::path(out_dir) / relative).string(), bytes));
    artefacts[relative] = {{"sha256", store::ComputeDigest(bytes).hash}, {"bytes", bytes.size()}};
    return absl::OkStatus();
  };

  // Visual: glb (glTF +Y up) + Draco stream + uncompressed PLY/STL.
  TriangleMesh gltf_mesh = mesh;
  for (Eigen::Vector3f& v : gltf_mesh.vertices) v = Eigen::Vector3f(v.x(), v.z(), -v.y());
  GlbOptions glb_options;
  glb_options.name = name;
  ASSIGN_OR_RETURN(GlbResult glb, EncodeDracoGlb(gltf_mesh, glb_options));
  if (glb.triangles != mesh.triangles.size())
    return absl::InternalError(
        absl::StrCat("Draco decodes ", glb.triangles, " triangles of ", mesh.triangles.size()));
  RETURN_IF_ERROR(write("visual.glb", glb.bytes));
  RETURN_IF_ERROR(write("mesh.drc", glb.draco));
  RETURN_IF_ERROR(write("mesh.ply", EncodeMeshPly(mesh)));
  RETURN_IF_ERROR(write("mesh.stl", EncodeBinaryStl(mesh, name)));

  // Collision: the hull and the convex parts; mass and inertia from the parts.
  // A flat or degenerate mesh has no hull: its bounding box, thickened, stands in; a mesh the
  // decomposition cannot voxelise gets its hull as the single part. The manifest says which.
  std::string collision_method = "convex decomposition";
  absl::StatusOr<TriangleMesh> hull_or = ConvexHull(mesh.vertices);
  if (!hull_or.ok()) {
    const float pad = std::max(1e-4f, 1e-3f * box.sizes().maxCoeff());
    std::vector<Eigen::Vector3f> corners;
    for (int c = 0; c < 8; ++c)
      corners.emplace_back(c & 1 ? box.max().x() + pad : box.min().x() - pad,
                           c & 2 ? box.max().y() + pad : box.min().y() - pad,
                           c & 4 ? box.max().z() + pad : box.min().z() - pad);
    hull_or = ConvexHull(corners);
    collision_method = "bounding box (the mesh spans no volume)";
  }
  if (!hull_or.ok()) return hull_or.status();
  const TriangleMesh hull = *std::move(hull_or);
  RETURN_IF_ERROR(write("collision/hull.stl", EncodeBinaryStl(hull, name + " hull")));
  std::vector<TriangleMesh> parts = {hull};
  if (collision_method == "convex decomposition") {
    absl::StatusOr<std::vector<TriangleMesh>> decomposed =
        ConvexDecomposition(mesh, options.decomposition);
    if (decomposed.ok())
      parts = *std::move(decomposed);
    else
      collision_method =
          absl::StrCat("convex hull (decomposition failed: ", decomposed.status().message(), ")");
  }
  RigidObjectModel model;
  model.name = name;
  model.visual_mesh = "mesh.stl";
  std::vector<MassProperties> part_mass;
  for (size_t p = 0; p < parts.size(); ++p) {
    const std::string file = absl::StrFormat("collision/part_%02d.stl", p);
    RETURN_IF_ERROR(write(file, EncodeBinaryStl(parts[p], absl::StrCat(name, " part ", p))));
    model.collision_meshes.push_back(file);
    part_mass.push_back(MeshMassProperties(parts[p], options.density));
  }
  model.mass = Combine(part_mass);
  const MassProperties mesh_mass = MeshMassProperties(mesh, options.density);
  double area = 0;
  Eigen::Vector3d color = Eigen::Vector3d::Zero();
  for (size_t f = 0; f < mesh.triangles.size() && mesh.colors.size() == mesh.vertices.size(); ++f) {
    const double a = mesh.TriangleArea(f);
    area += a;
    for (uint32_t v : mesh.triangles[f]) color += a / 3.0 * mesh.colors[v].cast<double>();
  }
  if (area > 0) model.color = (color / area).cast<float>();
  RETURN_IF_ERROR(write("object.urdf", UrdfXml(model)));
  RETURN_IF_ERROR(write("object.xml", MjcfXml(model)));

  // Surface samples with normals (area-weighted, seeded).
  std::vector<double> cumulative;
  double total = 0;
  for (size_t f = 0; f < mesh.triangles.size(); ++f)
    cumulative.push_back(total += mesh.TriangleArea(f));
  std::mt19937_64 rng(options.seed);
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  std::vector<Eigen::Vector3f> points, normals;
  for (int i = 0; i < options.surface_points && total > 0; ++i) {
    const size_t f = static_cast<size_t>(
        std::lower_bound(cumulative.begin(), cumulative.end(), u01(rng) * total) -
        cumulative.begin());
    const auto& tri = mesh.triangles[std::min(f, mesh.triangles.size() - 1)];
    double a = u01(rng), b = u01(rng);
    if (a + b > 1) {
      a = 1 - a;
      b = 1 - b;
    }
    const Eigen::Vector3f& p0 = mesh.vertices[tri[0]];
    const Eigen::Vector3f e1 = mesh.vertices[tri[1]] - p0, e2 = mesh.vertices[tri[2]] - p0;
    points.push_back(p0 + static_cast<float>(a) * e1 + static_cast<float>(b) * e2);
    normals.push_back(e1.cross(e2).normalized());
  }
  RETURN_IF_ERROR(write("points.ply", PointsPly(points, normals)));

  const Eigen::Quaterniond q(r);
  const json gaussians = in.value("gaussians", json::object());
  json out = {
      {"format", kExportFormat},
      {"id", id},
      {"units", scale.meters_per_unit ? "metres" : "scene units (unscaled)"},
      {"scale",
       {{"meters_per_unit", scale.meters_per_unit ? json(*scale.meters_per_unit) : json(nullptr)},
        {"scaled", scale.meters_per_unit.has_value()},
        {"source",
         scale.meters_per_unit ? scale.source : "none: the scene has no meters_per_unit"}}},
      {"world_from_object",
       {{"translation", Vec(s * t)}, {"quaternion_xyzw", {q.x(), q.y(), q.z(), q.w()}}}},
      {"object_frame", "origin at the object's centre, z up (the support normal), as in the scene"},
      {"gltf_from_object", "glTF is +Y up: (x, y, z) -> (x, z, -y)"},
      {"bounding_box",
       {{"min", Vec(box.min().cast<double>())},
        {"max", Vec(box.max().cast<double>())},
        {"extent", Vec(box.sizes().cast<double>())}}},
      {"prior", in.value("prior", "")},
      {"abstained", in.value("abstained", true)},
      {"completion",
       in.value("abstained", true) ? "raw crop (no completion hypothesis passed)" : "completed"},
      {"observed_share", 1.0 - gaussians.value("completed_share", 0.0)},
      {"completed_share", gaussians.value("completed_share", 0.0)},
      {"mesh",
       {{"vertices", mesh.vertices.size()},
        {"triangles", mesh.triangles.size()},
        {"degenerate_triangles_dropped", input_triangles - mesh.triangles.size()},
        {"volume", mesh_mass.volume}}},
      {"collision",
       {{"hull", "collision/hull.stl"},
        {"parts", model.collision_meshes},
        {"method", collision_method}}},
      {"inertial",
       {{"density_kg_m3", options.density},
        {"mass", model.mass.mass},
        {"center_of_mass", Vec(model.mass.center)},
        {"inertia",
         {{model.mass.inertia(0, 0), model.mass.inertia(0, 1), model.mass.inertia(0, 2)},
          {model.mass.inertia(1, 0), model.mass.inertia(1, 1), model.mass.inertia(1, 2)},
          {model.mass.inertia(2, 0), model.mass.inertia(2, 1), model.mass.inertia(2, 2)}}},
        {"from", "the convex collision parts"}}},
      {"surface_points", points.size()},
      {"artefacts", artefacts},
  };
  RETURN_IF_ERROR(WriteFileAtomically((fs::path(out_dir) / "manifest.json").string(), out.dump(1)));
  return out;
}

}  // namespace instascene::objects
