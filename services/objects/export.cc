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

// The completed object read back: its mesh moved into the object frame, in metres.
struct ObjectInput {
  json manifest;  // the completion's manifest.json
  Eigen::Isometry3d world_from_object;
  double meters_per_unit = 1;  // 1 when unscaled
  uint32_t id = 0;
  std::string name;   // object_<id>
  TriangleMesh mesh;  // object frame, metres; degenerate faces dropped
  size_t degenerate_dropped = 0;
  Eigen::AlignedBox3f box;  // of `mesh`
};

absl::StatusOr<ObjectInput> ReadObject(const std::string& object_dir, const MetricScale& scale) {
  ObjectInput o;
  const std::string manifest_path = (fs::path(object_dir) / "manifest.json").string();
  ASSIGN_OR_RETURN(std::string manifest_text, ReadFileBounded(manifest_path, 64 << 20));
  o.manifest = json::parse(manifest_text, nullptr, false);
  if (o.manifest.is_discarded() || !o.manifest.is_object())
    return absl::DataLossError(absl::StrCat(manifest_path, ": not a JSON object"));
  ASSIGN_OR_RETURN(o.world_from_object, ParsePose(o.manifest, manifest_path));
  ASSIGN_OR_RETURN(o.mesh, ReadMeshPly((fs::path(object_dir) / "mesh.ply").string()));
  if (o.mesh.triangles.empty())
    return absl::DataLossError(absl::StrCat(object_dir, "/mesh.ply: no triangles"));
  o.meters_per_unit = scale.meters_per_unit.value_or(1.0);
  if (!(o.meters_per_unit > 0))
    return absl::InvalidArgumentError("meters_per_unit must be positive");
  o.id = o.manifest.value("id", 0u);
  o.name = absl::StrCat("object_", o.id);

  const Eigen::Matrix3d r = o.world_from_object.linear();
  const Eigen::Vector3d t = o.world_from_object.translation();
  for (Eigen::Vector3f& v : o.mesh.vertices)
    v = (o.meters_per_unit * (r.transpose() * (v.cast<double>() - t))).cast<float>();
  // Faces with two corners at one position (marching cubes makes a few) have no area; Draco drops
  // them, so every artefact drops them and all agree on the triangle count.
  const size_t input_triangles = o.mesh.triangles.size();
  const auto& v = o.mesh.vertices;
  std::erase_if(o.mesh.triangles, [&](const std::array<uint32_t, 3>& f) {
    return v[f[0]] == v[f[1]] || v[f[1]] == v[f[2]] || v[f[0]] == v[f[2]];
  });
  if (o.mesh.triangles.empty())
    return absl::DataLossError(absl::StrCat(object_dir, "/mesh.ply: only degenerate triangles"));
  o.degenerate_dropped = input_triangles - o.mesh.triangles.size();
  for (const Eigen::Vector3f& p : o.mesh.vertices) o.box.extend(p);
  return o;
}

// Writes artefacts under one folder and records each one's digest and size.
class ArtefactWriter {
 public:
  explicit ArtefactWriter(std::string dir) : dir_(std::move(dir)) {}
  absl::Status Write(const std::string& relative, const std::string& bytes) {
    RETURN_IF_ERROR(WriteFileAtomically((fs::path(dir_) / relative).string(), bytes));
    artefacts_[relative] = {{"sha256", store::ComputeDigest(bytes).hash}, {"bytes", bytes.size()}};
    return absl::OkStatus();
  }
  const json& artefacts() const { return artefacts_; }

 private:
  std::string dir_;
  json artefacts_ = json::object();
};

// Visual: glb (glTF +Y up) + Draco stream + uncompressed PLY/STL.
absl::Status WriteVisual(const ObjectInput& o, ArtefactWriter& out) {
  TriangleMesh gltf_mesh = o.mesh;
  for (Eigen::Vector3f& v : gltf_mesh.vertices) v = Eigen::Vector3f(v.x(), v.z(), -v.y());
  GlbOptions glb_options;
  glb_options.name = o.name;
  ASSIGN_OR_RETURN(GlbResult glb, EncodeDracoGlb(gltf_mesh, glb_options));
  if (glb.triangles != o.mesh.triangles.size())
    return absl::InternalError(
        absl::StrCat("Draco decodes ", glb.triangles, " triangles of ", o.mesh.triangles.size()));
  RETURN_IF_ERROR(out.Write("visual.glb", glb.bytes));
  RETURN_IF_ERROR(out.Write("mesh.drc", glb.draco));
  RETURN_IF_ERROR(out.Write("mesh.ply", EncodeMeshPly(o.mesh)));
  return out.Write("mesh.stl", EncodeBinaryStl(o.mesh, o.name));
}

struct Collision {
  std::vector<TriangleMesh> parts;
  std::string method;
};

// The hull and the convex parts. A flat or degenerate mesh has no hull: its bounding box,
// thickened, stands in; a mesh the decomposition cannot voxelise gets its hull as the single
// part. `method` says which.
absl::StatusOr<Collision> CollisionParts(const ObjectInput& o, const ExportOptions& options,
                                         ArtefactWriter& out) {
  Collision c{{}, "convex decomposition"};
  absl::StatusOr<TriangleMesh> hull_or = ConvexHull(o.mesh.vertices);
  if (!hull_or.ok()) {
    const float pad = std::max(1e-4f, 1e-3f * o.box.sizes().maxCoeff());
    std::vector<Eigen::Vector3f> corners;
    for (int k = 0; k < 8; ++k)
      corners.emplace_back(k & 1 ? o.box.max().x() + pad : o.box.min().x() - pad,
                           k & 2 ? o.box.max().y() + pad : o.box.min().y() - pad,
                           k & 4 ? o.box.max().z() + pad : o.box.min().z() - pad);
    hull_or = ConvexHull(corners);
    c.method = "bounding box (the mesh spans no volume)";
  }
  if (!hull_or.ok()) return hull_or.status();
  RETURN_IF_ERROR(out.Write("collision/hull.stl", EncodeBinaryStl(*hull_or, o.name + " hull")));
  c.parts = {*std::move(hull_or)};
  if (c.method == "convex decomposition") {
    absl::StatusOr<std::vector<TriangleMesh>> decomposed =
        ConvexDecomposition(o.mesh, options.decomposition);
    if (decomposed.ok())
      c.parts = *std::move(decomposed);
    else
      c.method =
          absl::StrCat("convex hull (decomposition failed: ", decomposed.status().message(), ")");
  }
  return c;
}

// The mesh's area-weighted mean vertex colour; nullopt without colours or area.
std::optional<Eigen::Vector3f> MeanColor(const TriangleMesh& mesh) {
  double area = 0;
  Eigen::Vector3d color = Eigen::Vector3d::Zero();
  for (size_t f = 0; f < mesh.triangles.size() && mesh.colors.size() == mesh.vertices.size(); ++f) {
    const double a = mesh.TriangleArea(f);
    area += a;
    for (uint32_t v : mesh.triangles[f]) color += a / 3.0 * mesh.colors[v].cast<double>();
  }
  if (!(area > 0)) return std::nullopt;
  return (color / area).cast<float>();
}

// Collision parts, URDF and MJCF; returns the robot model (mass from the parts).
absl::StatusOr<RigidObjectModel> WriteRobotModels(const ObjectInput& o, const Collision& c,
                                                  double density, ArtefactWriter& out) {
  RigidObjectModel model;
  model.name = o.name;
  model.visual_mesh = "mesh.stl";
  std::vector<MassProperties> part_mass;
  for (size_t p = 0; p < c.parts.size(); ++p) {
    const std::string file = absl::StrFormat("collision/part_%02d.stl", p);
    RETURN_IF_ERROR(
        out.Write(file, EncodeBinaryStl(c.parts[p], absl::StrCat(o.name, " part ", p))));
    model.collision_meshes.push_back(file);
    part_mass.push_back(MeshMassProperties(c.parts[p], density));
  }
  model.mass = Combine(part_mass);
  if (std::optional<Eigen::Vector3f> color = MeanColor(o.mesh)) model.color = *color;
  RETURN_IF_ERROR(out.Write("object.urdf", UrdfXml(model)));
  RETURN_IF_ERROR(out.Write("object.xml", MjcfXml(model)));
  return model;
}

// `count` surface samples with their faces' normals, area-weighted, seeded.
void SampleSurface(const TriangleMesh& mesh, int count, uint64_t seed,
                   std::vector<Eigen::Vector3f>* points, std::vector<Eigen::Vector3f>* normals) {
  std::vector<double> cumulative;
  double total = 0;
  for (size_t f = 0; f < mesh.triangles.size(); ++f)
    cumulative.push_back(total += mesh.TriangleArea(f));
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  for (int i = 0; i < count && total > 0; ++i) {
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
    points->push_back(p0 + static_cast<float>(a) * e1 + static_cast<float>(b) * e2);
    normals->push_back(e1.cross(e2).normalized());
  }
}

json ScaleJson(const MetricScale& scale) {
  return {
      {"meters_per_unit", scale.meters_per_unit ? json(*scale.meters_per_unit) : json(nullptr)},
      {"scaled", scale.meters_per_unit.has_value()},
      {"source", scale.meters_per_unit ? scale.source : "none: the scene has no meters_per_unit"}};
}

json InertialJson(const MassProperties& m, double density) {
  return {{"density_kg_m3", density},
          {"mass", m.mass},
          {"center_of_mass", Vec(m.center)},
          {"inertia",
           {{m.inertia(0, 0), m.inertia(0, 1), m.inertia(0, 2)},
            {m.inertia(1, 0), m.inertia(1, 1), m.inertia(1, 2)},
            {m.inertia(2, 0), m.inertia(2, 1), m.inertia(2, 2)}}},
          {"from", "the convex collision parts"}};
}

// The export manifest (instascene.export/1).
json ExportManifest(const ObjectInput& o, const MetricScale& scale, const Collision& c,
                    const RigidObjectModel& model, double density, size_t surface_points,
                    const json& artefacts) {
  const Eigen::Quaterniond q(o.world_from_object.linear());
  const Eigen::Vector3d t = o.meters_per_unit * o.world_from_object.translation();
  const json gaussians = o.manifest.value("gaussians", json::object());
  const bool abstained = o.manifest.value("abstained", true);
  const double completed_share = gaussians.value("completed_share", 0.0);
  return {
      {"format", kExportFormat},
      {"id", o.id},
      {"units", scale.meters_per_unit ? "metres" : "scene units (unscaled)"},
      {"scale", ScaleJson(scale)},
      {"world_from_object",
       {{"translation", Vec(t)}, {"quaternion_xyzw", {q.x(), q.y(), q.z(), q.w()}}}},
      {"object_frame", "origin at the object's centre, z up (the support normal), as in the scene"},
      {"gltf_from_object", "glTF is +Y up: (x, y, z) -> (x, z, -y)"},
      {"bounding_box",
       {{"min", Vec(o.box.min().cast<double>())},
        {"max", Vec(o.box.max().cast<double>())},
        {"extent", Vec(o.box.sizes().cast<double>())}}},
      {"prior", o.manifest.value("prior", "")},
      {"abstained", abstained},
      {"completion", abstained ? "raw crop (no completion hypothesis passed)" : "completed"},
      {"observed_share", 1.0 - completed_share},
      {"completed_share", completed_share},
      {"mesh",
       {{"vertices", o.mesh.vertices.size()},
        {"triangles", o.mesh.triangles.size()},
        {"degenerate_triangles_dropped", o.degenerate_dropped},
        {"volume", MeshMassProperties(o.mesh, density).volume}}},
      {"collision",
       {{"hull", "collision/hull.stl"}, {"parts", model.collision_meshes}, {"method", c.method}}},
      {"inertial", InertialJson(model.mass, density)},
      {"surface_points", surface_points},
      {"artefacts", artefacts},
  };
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
  ASSIGN_OR_RETURN(const ObjectInput o, ReadObject(object_dir, scale));
  std::error_code ec;
  fs::create_directories(fs::path(out_dir) / "collision", ec);
  if (ec) return absl::UnavailableError(absl::StrCat(out_dir, ": ", ec.message()));
  ArtefactWriter out(out_dir);
  RETURN_IF_ERROR(WriteVisual(o, out));
  ASSIGN_OR_RETURN(const Collision collision, CollisionParts(o, options, out));
  ASSIGN_OR_RETURN(const RigidObjectModel model,
                   WriteRobotModels(o, collision, options.density, out));
  std::vector<Eigen::Vector3f> points, normals;
  SampleSurface(o.mesh, options.surface_points, options.seed, &points, &normals);
  RETURN_IF_ERROR(out.Write("points.ply", PointsPly(points, normals)));
  json manifest =
      ExportManifest(o, scale, collision, model, options.density, points.size(), out.artefacts());
  RETURN_IF_ERROR(
      WriteFileAtomically((fs::path(out_dir) / "manifest.json").string(), manifest.dump(1)));
  return manifest;
}

}  // namespace instascene::objects
