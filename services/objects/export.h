// services/objects/export.h: one completed object (the `complete` stage's folder: mesh.ply in the
// scene frame, manifest.json with world_from_object) as the artefacts robot stacks consume, in the
// object's frame (origin at the object's centre, z up) and in metres when the scene's scale is
// known:
//   visual.glb     glTF 2.0, Draco-compressed (KHR_draco_mesh_compression), vertex colours, +Y up:
//                  gltf = (x, z, -y) of the object frame (glTF's convention)
//   mesh.drc       the same Draco stream; mesh.ply (coloured) and mesh.stl uncompressed
//   collision/     hull.stl (Qhull) and part_NN.stl (approximate convex decomposition)
//   object.urdf, object.xml (MJCF)  visual + collision meshes, mass and inertia of the collision
//                  parts at `density` (kg/m³)
//   points.ply     surface samples with normals (x y z nx ny nz, float), for grasp planners
//   manifest.json  instascene.export/1: id, world_from_object (translation in metres +
//                  quaternion), oriented bounding box, metric scale and its source, observed vs
//                  completed share, prior, abstained, mass properties, every artefact's digest
// Without a metric scale everything stays in scene units and the manifest says "unscaled".
// Deterministic for a given input and seed.
#pragma once

#include <optional>
#include <string>

#include <nlohmann/json.hpp>

#include "absl/status/statusor.h"
#include "services/objects/convex_decomposition.h"

namespace instascene::objects {

inline constexpr char kExportFormat[] = "instascene.export/1";

struct ExportOptions {
  double density = 500;       // kg/m³ (a mid value for household objects: wood ~500-700)
  int surface_points = 4096;  // points.ply samples
  ConvexDecompositionOptions decomposition;
  uint64_t seed = 1;

  absl::Status Validate() const;
};

struct MetricScale {
  std::optional<double> meters_per_unit;  // absent: unscaled
  std::string source;                     // e.g. "scene.json meters_per_unit"
};

// Reads `object_dir` (a completed object), writes the artefacts into `out_dir` and returns the
// manifest (also written). InvalidArgument / DataLoss name the bad file.
absl::StatusOr<nlohmann::json> ExportObject(const std::string& object_dir, const MetricScale& scale,
                                            const ExportOptions& options,
                                            const std::string& out_dir);

}  // namespace instascene::objects
