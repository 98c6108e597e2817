// common/synth/cluttered_scene.h: procedural cluttered table-top scenes with exact ground truth.
//
// World frame: z up, metres. "Stuff" (floor, back wall, table) has instance id 0; objects have ids
// 1..N. The table stands against the wall and cameras only orbit the front half, so the backs of
// objects near the wall are never seen (the occluded parts in-situ generation must complete).
// Several identical objects stand side by side (the paper's bottles), and many objects touch.
// Deterministic from the seed. Stateless functions, thread-safe.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "common/geometry/camera.h"
#include "common/geometry/triangle_mesh.h"
#include "common/splat/gaussian_cloud.h"
#include "common/synth/primitives.h"
#include "common/synth/surfels.h"

namespace instascene {

struct ClutterOptions {
  uint64_t seed = 1;
  int objects = 8;  // number of object instances (>= 1)
  int views = 24;   // number of cameras
  int width = 160;  // image size, px
  int height = 120;
  size_t gaussians = 20000;     // surfels (objects + stuff) before the table refinement and
                                // the cones' apex surfels
  float stuff_fraction = 0.3f;  // share of surfels on floor, wall and table
  int duplicates = 3;           // identical objects side by side (0 or 1 = none)
  int sh_degree = 1;            // 0 or 1
  float fov_x_deg = 60.0f;      // horizontal field of view of every camera
  // Share of the (non-duplicate) objects drawn from the asymmetric shapes (mug, L-block, irregular
  // block); 0 keeps the original shape distribution (and every earlier scene) unchanged.
  float asymmetric_share = 0.0f;
  // Table-top surfels whose disc reaches an object are split into table_detail x table_detail
  // smaller ones (RefineTableNearObjects in the .cc says why); the scene then holds a few per cent
  // more than `gaussians`. 1 = none: the scenes generated before 2026-12-03, in which low objects
  // (bowls, tori) were partly painted over by the table.
  int table_detail = 3;

  absl::Status Validate() const;
};

// Named presets: "tiny" (unit tests), "small" (the default), "medium" (300k / 100 views /
// 640x480 / 20 objects), "large" (1M / 200 views / 1280x720 / 40 objects).
absl::StatusOr<ClutterOptions> ClutterPreset(const std::string& name);

struct SynthObject {
  int id = 0;        // instance id, 1..N
  std::string name;  // e.g. "bottle_3"
  ShapeSpec shape;
  Rigid3d world_from_object;  // x_world = world_from_object * (scale * x_object)
  float scale = 1.0f;         // uniform scale applied before world_from_object (composites)
  Appearance appearance;
  int duplicate_group = -1;   // objects sharing a group >= 0 are identical
  TriangleMesh mesh;          // complete surface, world frame (ground truth for completion)
  size_t first_gaussian = 0;  // its surfels are [first_gaussian, first_gaussian + num_gaussians)
  size_t num_gaussians = 0;
};

struct ClutterScene {
  GaussianCloud cloud;                 // 2DGS surfels
  std::vector<uint16_t> instance_ids;  // per Gaussian: 0 = stuff, else object id
  std::vector<SynthObject> objects;
  TriangleMesh stuff_mesh;  // floor, wall, table (world frame)
  // Per object (same order), only after DropUnseenSurfels: its complete surfels before the unseen
  // ones were dropped (the appearance ground truth of completion).
  std::vector<GaussianCloud> complete_surfels;
  std::vector<PinholeCamera> cameras;
  Eigen::Vector3d focus;  // point the cameras look at
};

absl::StatusOr<ClutterScene> GenerateClutterScene(const ClutterOptions& options);

}  // namespace instascene
