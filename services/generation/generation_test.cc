#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <random>

#include <gtest/gtest.h>

#include <atomic>
#include <optional>

#include "common/geometry/camera.h"
#include "common/mesh/mesh_volume.h"
#include "common/mesh/ray_caster.h"
#include "common/mesh/surfel_mesh.h"
#include "common/raster/rasterizer.h"
#include "common/rpc/server.h"
#include "common/splat/gaussian_ply.h"
#include "common/synth/cluttered_scene.h"
#include "common/synth/observed_surfels.h"
#include "common/synth/primitives.h"
#include "common/synth/surfels.h"
#include "services/generation/completion.h"
#include "services/generation/diffusion/analytic_denoiser.h"
#include "services/generation/diffusion/grpc_denoiser.h"
#include "services/generation/diffusion/latent_codec.h"
#include "services/generation/free_space.h"
#include "services/generation/geometric_prior.h"
#include "services/generation/object_mesh.h"
#include "services/generation/seen_through.h"
#include "services/generation/stage.h"
#include "services/generation/support_completion.h"
#include "services/generation/symmetry.h"

namespace instascene::generation {
namespace {

constexpr double kPi = 3.14159265358979323846;

// One object on a table (z = 0 plane), seen by cameras on the front half only (azimuth -70..70 deg
// around +x): the back and the underside are never seen. Surfels facing away from every camera are
// dropped (the object is convex or nearly so, so that is its visible part).
struct PartialObject {
  GaussianCloud cloud;           // table + observed object surfels
  std::vector<uint32_t> labels;  // 1 = object
  std::vector<PinholeCamera> cameras;
};

PartialObject MakePartialObject(const TriangleMesh& object_mesh, size_t count, uint64_t seed,
                                double front_half_angle_deg = 70) {
  PartialObject out;
  out.cloud.num_scales = 2;
  out.cloud.sh_degree = 0;
  std::mt19937_64 rng(seed);
  Appearance appearance;
  appearance.pattern = TexturePattern::kSolid;
  TriangleMesh table = MakeRectangle(1.5f, 1.5f, 8, 8);
  GaussianCloud all;
  all.num_scales = 2;
  AppendSurfels(table, 6000, appearance, SurfelSampling{}, rng, &all);
  const size_t table_count = all.size();
  AppendSurfels(object_mesh, count, appearance, SurfelSampling{}, rng, &all);
  for (int k = 0; k < 9; ++k) {
    const double azimuth = -front_half_angle_deg + 2 * front_half_angle_deg * k / 8.0;
    out.cameras.push_back(
        OrbitCamera({0, 0, 0.1}, {0, 0, 1}, 1.2, azimuth, 20.0 + 10 * (k % 3), 128, 96, 55.0));
  }
  std::vector<uint32_t> keep;
  for (uint32_t g = 0; g < all.size(); ++g) {
    if (g < table_count) {
      keep.push_back(g);
      continue;
    }
    const Eigen::Vector3f p(&all.positions[3 * g]);
    const float* q = &all.rotations[4 * g];
    const Eigen::Vector3f n =
        RotationFromQuaternionWxyz(q[0], q[1], q[2], q[3]).col(2).cast<float>();
    bool facing = false;
    for (const PinholeCamera& c : out.cameras) {
      const Eigen::Vector3f to_camera = c.CenterInWorld().cast<float>() - p;
      // Outward normals: the mesh normal of a closed lathe / box points out.
      facing |= n.dot(to_camera) > 0.05f * to_camera.norm();
    }
    if (facing) keep.push_back(g);
  }
  out.cloud = all.Subset(keep);
  out.labels.assign(out.cloud.size(), 0);
  for (size_t i = 0; i < keep.size(); ++i) out.labels[i] = keep[i] >= table_count ? 1 : 0;
  return out;
}

TriangleMesh Bottle() {
  ShapeSpec spec;
  spec.kind = ShapeKind::kBottle;
  spec.size = {0.05f, 0, 0.25f};
  return MakeShapeMesh(spec, 48);
}

// An L of two boxes of different heights: no vertical mirror plane, no axis.
TriangleMesh LBlock() {
  ShapeSpec a, b;
  a.kind = b.kind = ShapeKind::kBox;
  a.size = {0.20f, 0.06f, 0.12f};
  b.size = {0.06f, 0.14f, 0.07f};
  TriangleMesh mesh = MakeShapeMesh(a);
  TriangleMesh arm = MakeShapeMesh(b);
  Rigid3d shift;
  shift.translation = {0.07, 0.10, 0.0};
  arm.Transform(shift);
  mesh.Append(arm);
  return mesh;
}

struct Detected {
  ObjectFrame frame;
  std::vector<SymmetryHypothesis> hypotheses;
};

// The free space of a test scene around `frame`, carved against all its surfels (the caster is
// kept beside the grid, which points at it).
struct SceneFreeSpace {
  std::unique_ptr<RayCaster> caster;
  std::optional<FreeSpaceGrid> grid;
};

SceneFreeSpace CarveScene(const PartialObject& scene, const ObjectFrame& frame) {
  SceneFreeSpace out;
  std::vector<uint32_t> all(scene.cloud.size());
  for (uint32_t g = 0; g < all.size(); ++g) all[g] = g;
  auto caster = RayCaster::Create(SurfelDiscs(scene.cloud, all, SurfelDiscOptions{}));
  EXPECT_TRUE(caster.ok());
  if (!caster.ok()) return out;
  out.caster = std::move(*caster);
  auto grid = FreeSpaceGrid::Carve(scene.cameras, *out.caster, frame, FreeSpaceOptions{});
  EXPECT_TRUE(grid.ok());
  if (grid.ok()) out.grid = std::move(*grid);
  return out;
}

// The prior's input for instance 1 of a test scene: its frame, surfels and carved free space
// (no seen-through test: the grid alone).
struct PriorFixture {
  explicit PriorFixture(const PartialObject& scene) {
    auto split = SplitInstance(scene.labels, 1, 50);
    EXPECT_TRUE(split.ok());
    if (!split.ok()) return;
    input.frame = ComputeObjectFrame(scene.cloud, *split, scene.cameras);
    space = CarveScene(scene, input.frame);
    instance = scene.cloud.Subset(split->instance);
    input.instance = &instance;
    if (space.grid.has_value()) input.free_space = &*space.grid;
  }
  PriorFixture(const PriorFixture&) = delete;
  PriorFixture& operator=(const PriorFixture&) = delete;
  bool ok() const { return input.free_space != nullptr; }
  SceneFreeSpace space;
  GaussianCloud instance;
  PriorInput input;
};

// Copies of the scene's last surfels (the object's), moved to `targets` and labelled as the
// object: a neighbour's surfels the segmentation gave it. They come last in the instance.
void AppendObjectSurfelsAt(const std::vector<Eigen::Vector3f>& targets, PartialObject* scene) {
  const size_t n_scene = scene->cloud.size();
  std::vector<uint32_t> keep(n_scene);
  std::iota(keep.begin(), keep.end(), 0u);
  for (size_t i = 0; i < targets.size(); ++i) keep.push_back(keep[n_scene - 1 - i]);
  scene->cloud = scene->cloud.Subset(keep);
  for (size_t i = 0; i < targets.size(); ++i) {
    for (int k = 0; k < 3; ++k) scene->cloud.positions[3 * (n_scene + i) + k] = targets[i][k];
  }
  scene->labels.resize(scene->cloud.size(), 1);
}

Detected Detect(const PartialObject& scene, const SymmetryOptions& options = {}) {
  auto split = SplitInstance(scene.labels, 1, 50);
  EXPECT_TRUE(split.ok());
  Detected d;
  d.frame = ComputeObjectFrame(scene.cloud, *split, scene.cameras);
  const SceneFreeSpace space = CarveScene(scene, d.frame);
  std::vector<Eigen::Vector3f> points, normals;
  for (uint32_t g : split->instance) {
    points.emplace_back(&scene.cloud.positions[3 * g]);
    const float* q = &scene.cloud.rotations[4 * g];
    normals.push_back(RotationFromQuaternionWxyz(q[0], q[1], q[2], q[3]).col(2).cast<float>());
  }
  d.hypotheses = DetectSymmetries(points, normals, d.frame, *space.grid, options);
  return d;
}

// A wall with a small hole (about two rays wide), seen from the front: with hole closing the rays
// that slip through do not carve the space behind it; past the wall's edge (a silhouette) they do.
TEST(FreeSpace, RaysThroughSmallHolesDoNotCarve) {
  const TriangleMesh grid = MakeRectangle(0.12f, 0.12f, 80, 80);  // z = 0, cells of 1.5 mm
  TriangleMesh wall = grid;
  wall.triangles.clear();
  for (const auto& t : grid.triangles) {
    const Eigen::Vector3f c = (grid.vertices[t[0]] + grid.vertices[t[1]] + grid.vertices[t[2]]) / 3;
    if (std::abs(c.x()) > 0.0015f || std::abs(c.y()) > 0.0015f) wall.triangles.push_back(t);
  }
  ASSERT_EQ(wall.triangles.size() + 8, grid.triangles.size());
  auto caster = RayCaster::Create(wall);
  ASSERT_TRUE(caster.ok());
  const std::vector<PinholeCamera> cameras = {
      OrbitCamera({0, 0, 0}, {0, 0, 1}, 1.0, 0, 89, 640, 640, 50)};  // rays 1.5 mm apart
  ObjectFrame frame;
  frame.center = Eigen::Vector3f(0, 0, -0.1f);
  frame.radius = 0.05f;
  auto carved = [&](int hole_rays, const Eigen::Vector3f& at) {
    FreeSpaceOptions options;
    options.hole_rays = hole_rays;
    options.min_views = 1;
    auto g = FreeSpaceGrid::Carve(cameras, **caster, frame, options);
    EXPECT_TRUE(g.ok());
    int views = 0;
    for (float z = -0.05f; z > -0.15f; z -= 0.005f)
      views += g->FreeViews(at + Eigen::Vector3f(0, 0, z));
    return views;
  };
  const Eigen::Vector3f behind_hole(0, 0, 0), beside_wall(0.08f, 0, 0);
  EXPECT_GT(carved(0, behind_hole), 0);  // without closing the hole's rays carve behind it
  EXPECT_EQ(carved(1, behind_hole), 0);
  EXPECT_GT(carved(1, beside_wall), 0);  // past the wall's edge rays still carve
}

// The lowest band seen of a sphere resting on its support (latitudes -50 to -35 degrees, normals
// leaning down 35-50 degrees): straight down, its walls stand a skirt up to 11 mm outside the
// sphere; down their own slope (a tangent, so within 4 mm of it) they never move
// outwards, whichever way the normals point. The upper band (widening downwards) and a
// cylinder's walls (horizontal normals) go straight down either way.
TEST(SupportCompletion, WallsLeaningDownFollowTheirSlope) {
  ObjectFrame frame;
  frame.center = Eigen::Vector3f(0, 0, 0.05f);
  frame.radius = 0.05f;
  frame.has_support = true;
  frame.support_height = 0.0f;
  frame.spacing = 0.003f;
  auto band = [&](bool sphere) {
    std::vector<Eigen::Vector3f> positions;
    std::vector<Eigen::Matrix3f> rotations;
    std::vector<uint32_t> sources;
    for (float latitude = -50; latitude <= -35; latitude += 3) {
      const float phi = latitude * kPi / 180;
      for (int k = 0; k < 60; ++k) {
        const float a = 2 * kPi * k / 60;
        const Eigen::Vector3f radial(std::cos(a), std::sin(a), 0);
        const Eigen::Vector3f n =
            sphere
                ? Eigen::Vector3f(std::cos(phi) * radial + std::sin(phi) * Eigen::Vector3f::UnitZ())
                : radial;
        const Eigen::Vector3f p =
            sphere ? Eigen::Vector3f(frame.center + frame.radius * n)
                   : Eigen::Vector3f(0.03f * radial + Eigen::Vector3f(0, 0, 0.05f + 0.02f * phi));
        Eigen::Matrix3f r;
        const Eigen::Vector3f u = Eigen::Vector3f::UnitZ().cross(n).normalized();
        r << u, n.cross(u), n;
        positions.push_back(p);
        rotations.push_back(r);
        sources.push_back(static_cast<uint32_t>(sources.size()));
      }
    }
    return std::make_tuple(positions, rotations, sources);
  };
  const auto [positions, rotations, sources] = band(true);
  const std::vector<SurfelCandidate> straight = WallExtension(positions, rotations, sources, frame);
  const std::vector<SurfelCandidate> sloped =
      WallExtension(positions, rotations, sources, frame, 0.26f);
  ASSERT_FALSE(straight.empty());
  ASSERT_EQ(sloped.size(), straight.size());
  auto off_sphere = [&](const SurfelCandidate& c) {
    return (c.position - frame.center).norm() - frame.radius;
  };
  auto horizontal = [](const Eigen::Vector3f& p) { return std::hypot(p.x(), p.y()); };
  float worst_straight = 0, worst_sloped = 0;
  for (size_t i = 0; i < straight.size(); ++i) {
    worst_straight = std::max(worst_straight, std::abs(off_sphere(straight[i])));
    worst_sloped = std::max(worst_sloped, std::abs(off_sphere(sloped[i])));
    EXPECT_LE(horizontal(sloped[i].position), horizontal(positions[sloped[i].source]) + 1e-6f);
  }
  EXPECT_GT(worst_straight, 0.010f);
  EXPECT_LT(worst_sloped, 0.005f);
  // About the ball's vertical axis: along its curvature, on the ball, down to the support.
  const std::vector<SurfelCandidate> curved = WallExtension(
      positions, rotations, sources, frame, 0.26f, Eigen::Vector3f(0.0f, 0.0f, 0.02f));
  ASSERT_FALSE(curved.empty());
  float worst_curved = 0, lowest = 1;
  for (const SurfelCandidate& c : curved) {
    worst_curved = std::max(worst_curved, std::abs(off_sphere(c)));
    lowest = std::min(lowest, c.position.z());
    // The candidate's normal is the ball's.
    EXPECT_GT(std::abs(c.rotation.col(2).dot((c.position - frame.center).normalized())), 0.999f);
  }
  EXPECT_LT(worst_curved, 1e-4f);
  EXPECT_LT(lowest, 0.004f);
  // Whichever way the normals point (2DGS surfels carry no outside): the same candidates.
  std::vector<Eigen::Matrix3f> flipped = rotations;
  for (Eigen::Matrix3f& r : flipped) r.col(2) = -r.col(2);
  const std::vector<SurfelCandidate> flipped_sloped =
      WallExtension(positions, flipped, sources, frame, 0.26f);
  ASSERT_EQ(flipped_sloped.size(), sloped.size());
  for (size_t i = 0; i < sloped.size(); ++i) {
    EXPECT_TRUE(flipped_sloped[i].position.isApprox(sloped[i].position));
  }
  // The upper band of the same sphere as the lowest seen (a shoulder: it widens downwards) goes
  // straight down, either sign of normal.
  std::vector<Eigen::Vector3f> upper = positions;
  std::vector<Eigen::Matrix3f> upper_rotations = rotations, upper_flipped = flipped;
  for (size_t i = 0; i < upper.size(); ++i) {
    upper[i].z() = 2 * frame.center.z() - upper[i].z();
    for (Eigen::Matrix3f* r : {&upper_rotations[i], &upper_flipped[i]}) r->row(2) = -r->row(2);
  }
  const std::vector<SurfelCandidate> shoulder =
      WallExtension(upper, upper_rotations, sources, frame);
  for (const auto& rs : {upper_rotations, upper_flipped}) {
    const std::vector<SurfelCandidate> c = WallExtension(upper, rs, sources, frame, 0.26f);
    ASSERT_EQ(c.size(), shoulder.size());
    for (size_t i = 0; i < c.size(); ++i) EXPECT_TRUE(c[i].position.isApprox(shoulder[i].position));
  }
  const auto [walls, wall_rotations, wall_sources] = band(false);
  const std::vector<SurfelCandidate> a = WallExtension(walls, wall_rotations, wall_sources, frame);
  const std::vector<SurfelCandidate> b =
      WallExtension(walls, wall_rotations, wall_sources, frame, 0.26f);
  ASSERT_EQ(a.size(), b.size());
  ASSERT_FALSE(a.empty());
  for (size_t i = 0; i < a.size(); ++i) EXPECT_TRUE(a[i].position.isApprox(b[i].position));
}

// The support cap fills the footprint of the lower walls and stops at them: a cylinder's wall of
// surfels (radius 5 cm, 4 mm apart) gets a cap no wider than the wall plus half a grid cell (the
// cap's cells are 1.5 spacings; the dilation that keeps the outside from leaking in between the
// wall's surfels is taken back), and covers the inside.
TEST(SupportCompletion, TheCapFillsTheFootprintWithoutOverhangingTheWalls) {
  ObjectFrame frame;
  frame.center = Eigen::Vector3f(0.2f, -0.1f, 0.05f);
  frame.radius = 0.08f;
  frame.has_support = true;
  frame.support_height = 0.0f;
  frame.spacing = 0.004f;
  const float wall = 0.05f;
  std::vector<Eigen::Vector3f> positions;
  std::vector<uint32_t> sources;
  const int around = static_cast<int>(2 * M_PI * wall / frame.spacing);
  for (float z = 0.002f; z < 0.1f; z += frame.spacing) {
    for (int k = 0; k < around; ++k) {
      const double a = 2 * M_PI * k / around;
      positions.push_back(frame.center + Eigen::Vector3f(wall * std::cos(a), wall * std::sin(a),
                                                         z - frame.center.z()));
      sources.push_back(static_cast<uint32_t>(sources.size()));
    }
  }
  auto caster = RayCaster::Create(MakeRectangle(0.1f, 0.1f, 2, 2));
  ASSERT_TRUE(caster.ok());
  auto grid = FreeSpaceGrid::Carve({}, **caster, frame, FreeSpaceOptions{});  // nothing seen
  ASSERT_TRUE(grid.ok()) << grid.status();
  const std::vector<SurfelCandidate> cap = SupportCap(positions, sources, frame, *grid);
  ASSERT_FALSE(cap.empty());
  const float cell = 1.5f * frame.spacing;
  const double disc_cells = M_PI * wall * wall / (cell * cell);  // the disc's area in cells
  float widest = 0;
  for (const SurfelCandidate& c : cap) {
    const Eigen::Vector3f q = c.position - frame.center;
    widest = std::max(widest, std::hypot(q.x(), q.y()));
    EXPECT_NEAR(c.position.z(), 0.25f * frame.spacing, 1e-5f);
  }
  EXPECT_LE(widest, wall + 0.75f * cell)
      << "cap " << cap.size() << " cells for a disc of "
      << disc_cells;  // a cell's centre in a cell the wall crosses
  EXPECT_GE(widest, wall - 1.5f * cell);
  EXPECT_GT(cap.size(), 0.9 * disc_cells);
  EXPECT_LT(cap.size(), 1.25 * disc_cells);
}

// One blurred surfel (sigma 100x the spacing, opaque, centred inside a sphere of surfels) made a
// brim of false surface in the fused mesh; clamped to 3 spacings for meshing it is hidden inside.
// Open fusion shows the brim itself (the closed one may average a thin plate away; the clamp's
// effect on closed meshes is measured in RESULTS.md).
TEST(ObjectMesh, ABlurredSurfelMakesNoSheetOfFalseSurface) {
  ShapeSpec sphere;
  sphere.kind = ShapeKind::kSphere;
  sphere.size = {0.05f, 0, 0};
  GaussianCloud object;
  object.num_scales = 2;
  object.sh_degree = 0;
  std::mt19937_64 rng(5);
  const size_t count = 3000;
  AppendSurfels(MakeShapeMesh(sphere, 32), count, Appearance{}, SurfelSampling{}, rng, &object);
  AppendSurfels(MakeRectangle(0.001f, 0.001f, 1, 1), 1, Appearance{}, SurfelSampling{}, rng,
                &object);  // horizontal, at the sphere's centre
  const size_t blur = object.size() - 1;
  ObjectFrame frame;
  frame.radius = 0.06f;
  frame.spacing = std::sqrt(4 * kPi * 0.05f * 0.05f / count);  // about 3.2 mm
  object.log_scales[2 * blur] = object.log_scales[2 * blur + 1] = std::log(100 * frame.spacing);
  object.opacity_logits[blur] = std::log(0.999f / 0.001f);
  auto width = [&](float max_scale_spacings) {
    MeshingOptions options;
    options.size_px = 96;
    options.max_scale_spacings = max_scale_spacings;
    options.closed = false;
    auto mesh = MeshObject(object, frame, options, 2);
    EXPECT_TRUE(mesh.ok()) << mesh.status();
    Eigen::AlignedBox3f box;
    for (const Eigen::Vector3f& v : mesh->vertices) box.extend(v);
    return box.sizes().head<2>().maxCoeff();
  };
  EXPECT_GT(width(0.0f), 0.14f);  // unclamped: a brim far past the 10 cm sphere
  EXPECT_LT(width(3.0f), 0.11f);
}

// A 8 x 6 x 5 cm box of surfels, and the volume IoU (48^3, ray parity) of a mesh of them.
struct SurfelBox {
  SurfelBox(size_t count, const SurfelSampling& sampling, uint64_t seed) {
    ShapeSpec box;
    box.kind = ShapeKind::kBox;
    box.size = {0.08f, 0.06f, 0.05f};
    truth = MakeShapeMesh(box);
    surfels.num_scales = 2;
    surfels.sh_degree = 0;
    std::mt19937_64 rng(seed);
    AppendSurfels(truth, count, Appearance{}, sampling, rng, &surfels);
    bounds = truth.Bounds();
    frame.center = bounds.center();
    frame.radius = 0.5f * bounds.sizes().norm();
    frame.spacing = std::sqrt(2 * (0.08f * 0.06f + 0.08f * 0.05f + 0.06f * 0.05f) / count);
  }
  double MeshIou(const GaussianCloud& object, const MeshingOptions& options) const {
    auto mesh = MeshObject(object, frame, options, 2);
    EXPECT_TRUE(mesh.ok()) << mesh.status();
    if (!mesh.ok()) return 0;
    const Eigen::AlignedBox3f grid(bounds.min() - Eigen::Vector3f::Constant(0.02f),
                                   bounds.max() + Eigen::Vector3f::Constant(0.02f));
    auto result = VoxelizeByRayParity(*mesh, grid, 48);
    auto expected = VoxelizeByRayParity(truth, grid, 48);
    EXPECT_TRUE(result.ok() && expected.ok());
    if (!result.ok() || !expected.ok()) return 0;
    size_t both = 0, either = 0;
    for (size_t i = 0; i < result->size(); ++i) {
      both += (*result)[i] && (*expected)[i];
      either += (*result)[i] || (*expected)[i];
    }
    return static_cast<double>(both) / std::max<size_t>(either, 1);
  }
  TriangleMesh truth;
  GaussianCloud surfels;
  Eigen::AlignedBox3f bounds;
  ObjectFrame frame;
};

// Sparse surfels (sigma 0.35 of their spacing) leave gaps where a meshing render's alpha is below
// the carving's 0.9; carving through them would cut into the box. Closing the object's pixels
// before the distance transform (MeshingOptions::empty_close_px) keeps it whole.
TEST(ObjectMesh, CarvingSeesNoEmptinessInTheGapsBetweenSparseSurfels) {
  SurfelSampling sparse;
  sparse.scale_factor = 0.35f;
  const SurfelBox box(2500, sparse, 7);
  auto box_iou = [&](float close_px, int carve_views) {
    MeshingOptions options;
    options.carve_views = carve_views;
    options.empty_close_px = close_px;
    return box.MeshIou(box.surfels, options);
  };
  const double uncarved = box_iou(9.0f, 0), closed = box_iou(9.0f, 2), open = box_iou(0.0f, 2);
  EXPECT_GT(uncarved, 0.8);
  EXPECT_GT(closed, uncarved - 0.03);  // the closed carve costs nothing here
  EXPECT_LT(open, closed - 0.1);       // carving through the gaps cuts the box (to nothing)
}

// A surfel's footprint reaches past the edges of a box's top face: the fused top stands above the
// highest surfel centre (on the true top) unless it is lowered onto it.
TEST(ObjectMesh, NothingStandsAboveTheHighestSurfel) {
  const SurfelBox box(4000, SurfelSampling{}, 5);
  float highest = -1;
  for (uint32_t g = 0; g < box.surfels.size(); ++g) {
    highest = std::max(highest, box.surfels.positions[3 * g + 2]);
  }
  auto top = [&](bool clamp) {
    MeshingOptions options;
    options.top_at_highest_surfel = clamp;
    auto mesh = MeshObject(box.surfels, box.frame, options, 2);
    EXPECT_TRUE(mesh.ok()) << mesh.status();
    float z = -1;
    for (const Eigen::Vector3f& v : mesh->vertices) z = std::max(z, v.z());
    return z;
  };
  EXPECT_GT(top(false), highest + 0.001f);
  EXPECT_LE(top(true), highest + 1e-6f);
  EXPECT_NEAR(highest, box.bounds.max().z(), 1e-4f);
}

// Likewise past the box's side faces: the fused sides stand outside the outermost surfel centres
// (on the true faces) unless clamped to the centres' polygon. Where the renders' visual hull
// encloses the object (an unseen side closed past the surfels) the clamp is not applied.
TEST(ObjectMesh, NoSideStandsPastTheOutermostSurfels) {
  const SurfelBox box(4000, SurfelSampling{}, 5);
  Eigen::AlignedBox3f centres;
  for (uint32_t g = 0; g < box.surfels.size(); ++g) {
    centres.extend(Eigen::Vector3f(&box.surfels.positions[3 * g]));
  }
  auto overhang = [&](bool clamp, bool hull) {  // the most a vertex stands past them sideways
    MeshingOptions options;
    options.sides_within_surfels = clamp;
    auto mesh = MeshObject(box.surfels, box.frame, options, 2,
                           hull ? [](const Eigen::Vector3f&) { return false; }
                                : std::function<bool(const Eigen::Vector3f&)>{});
    EXPECT_TRUE(mesh.ok()) << mesh.status();
    float out = -1;
    for (const Eigen::Vector3f& v : mesh->vertices) {
      const Eigen::Vector2f past =
          (v - centres.max()).head<2>().cwiseMax(centres.min().head<2>() - v.head<2>());
      out = std::max(out, past.maxCoeff());
    }
    return out;
  };
  EXPECT_GT(overhang(false, false), 0.001f);
  EXPECT_LE(overhang(true, false), 1e-6f);
  EXPECT_GT(overhang(true, true), 0.001f);
  EXPECT_NEAR(centres.max().x(), box.bounds.max().x(), 1e-4f);
}

// A completed shell with a refused patch: a hole in a box's top, wider than the closing's gap
// rule passes. Views looking into it see the inner sides of the far walls; fused, those depths
// mark the inside as empty and the box comes out hollow. Fusing only the surfels whose outer
// side faces each view keeps it solid (MeshingOptions::cull_inner_sides).
TEST(ObjectMesh, AViewThroughAHoleInTheShellDoesNotHollowIt) {
  const SurfelBox box(4000, SurfelSampling{}, 11);
  // The hole: every surfel of the top face within 2 cm of its centre (4 cm wide; the gap rule
  // keeps holes up to 16 voxels of R / 40, 2.5 cm, closed).
  std::vector<uint32_t> kept;
  const Eigen::Vector3f top(box.bounds.center().x(), box.bounds.center().y(), box.bounds.max().z());
  for (uint32_t g = 0; g < box.surfels.size(); ++g) {
    const Eigen::Vector3f p(&box.surfels.positions[3 * g]);
    if (std::abs(p.z() - top.z()) < 0.002f && (p - top).norm() < 0.02f) continue;
    kept.push_back(g);
  }
  ASSERT_LT(kept.size(), box.surfels.size() - 100);
  const GaussianCloud object = box.surfels.Subset(kept);
  MeshingOptions options;
  options.cull_inner_sides = false;
  const double hollow = box.MeshIou(object, options);
  options.cull_inner_sides = true;
  const double solid = box.MeshIou(object, options);
  EXPECT_LT(hollow, 0.6);  // 0.39 when written
  EXPECT_GT(solid, 0.9);   // 0.96
}

TEST(ObjectFrame, UpFromTheSupportAndSupportHeight) {
  const PartialObject scene = MakePartialObject(Bottle(), 4000, 3);
  auto split = SplitInstance(scene.labels, 1, 50);
  ASSERT_TRUE(split.ok());
  const ObjectFrame frame = ComputeObjectFrame(scene.cloud, *split, scene.cameras);
  EXPECT_GT(frame.up.z(), std::cos(2 * kPi / 180));  // within 2 degrees of the truth
  ASSERT_TRUE(frame.has_support);
  EXPECT_NEAR(frame.support_height, 0.0f, 0.005f);
  EXPECT_GT(frame.spacing, 0);
}

// A bottle with a box (label 2) standing 2 mm beside it at +x: the bottle's surfels facing the box
// are surrounded by its label, those on the far side and those over the bare table are not.
TEST(ObjectFrame, NeighbourLabelledMarksTheSurfelsFacingATouchingNeighbour) {
  PartialObject scene = MakePartialObject(Bottle(), 4000, 5);
  ShapeSpec box;
  box.kind = ShapeKind::kBox;
  box.size = {0.04f, 0.04f, 0.1f};
  TriangleMesh mesh = MakeShapeMesh(box);
  Rigid3d shift;
  shift.translation = {0.072, 0.0, 0.0};
  mesh.Transform(shift);
  std::mt19937_64 rng(5);
  const size_t before = scene.cloud.size();
  AppendSurfels(mesh, 3000, Appearance{}, SurfelSampling{}, rng, &scene.cloud);
  scene.labels.resize(before, 0);
  scene.labels.resize(scene.cloud.size(), 2);
  auto split = SplitInstance(scene.labels, 1, 50);
  ASSERT_TRUE(split.ok());
  const ObjectFrame frame = ComputeObjectFrame(scene.cloud, *split, scene.cameras);
  const std::vector<uint8_t> marked = NeighbourLabelled(scene.cloud, scene.labels, *split, frame);
  ASSERT_EQ(marked.size(), split->instance.size());
  size_t facing = 0, facing_marked = 0, far_marked = 0;
  for (size_t i = 0; i < marked.size(); ++i) {
    const Eigen::Vector3f p(&scene.cloud.positions[3 * split->instance[i]]);
    if (p.x() > 0.045f && std::abs(p.y()) < 0.01f && p.z() > 0.01f && p.z() < 0.09f) {
      ++facing;
      facing_marked += marked[i];
    }
    if (p.x() < 0.02f) far_marked += marked[i];
  }
  ASSERT_GT(facing, 10u);
  EXPECT_GT(facing_marked, 0.9 * facing);
  EXPECT_EQ(far_marked, 0u);
  // Without the neighbour's label (background), nothing is marked.
  std::fill(scene.labels.begin() + before, scene.labels.end(), 0u);
  const std::vector<uint8_t> none = NeighbourLabelled(scene.cloud, scene.labels, *split, frame);
  EXPECT_EQ(std::count(none.begin(), none.end(), 1), 0);
  // Nor when the box carries the bottle's own label outside the instance (as strays that left it
  // do): the split above already holds the box's surfels as occluders.
  std::fill(scene.labels.begin() + before, scene.labels.end(), 1u);
  const std::vector<uint8_t> own = NeighbourLabelled(scene.cloud, scene.labels, *split, frame);
  EXPECT_EQ(std::count(own.begin(), own.end(), 1), 0);
}

// A segmentation that gave the bottle the table's surfels around its base: they leave the
// instance (the bottle's own surfels all stay), and the support and bottom are the table's.
TEST(ObjectFrame, TheSupportsSurfelsAroundTheBaseLeaveTheInstance) {
  PartialObject scene = MakePartialObject(Bottle(), 4000, 3);
  auto clean = SplitInstance(scene.labels, 1, 50);
  ASSERT_TRUE(clean.ok());
  size_t ring = 0;
  for (uint32_t g = 0; g < scene.cloud.size(); ++g) {
    const Eigen::Vector3f p(&scene.cloud.positions[3 * g]);
    const float r = Eigen::Vector2f(p.x(), p.y()).norm();
    if (scene.labels[g] == 0 && std::abs(p.z()) < 1e-4f && r < 0.1f) {
      scene.labels[g] = 1;
      ++ring;
    }
  }
  ASSERT_GT(ring, 5u);
  auto split = SplitInstance(scene.labels, 1, 50);
  ASSERT_TRUE(split.ok());
  const ObjectFrame frame = ComputeObjectFrame(scene.cloud, *split, scene.cameras);
  ASSERT_TRUE(frame.has_support);
  EXPECT_EQ(RemoveSupportSurfels(scene.cloud, frame, &*split), ring);
  EXPECT_EQ(split->instance, clean->instance);
  EXPECT_EQ(split->outliers, ring);
  EXPECT_EQ(split->instance.size() + split->occluders.size(), scene.cloud.size());
  const ObjectFrame again = ComputeObjectFrame(scene.cloud, *split, scene.cameras);
  EXPECT_NEAR(again.support_height, 0.0f, 0.005f);
  EXPECT_EQ(RemoveSupportSurfels(scene.cloud, again, &*split), 0u);  // nothing more to move
}

// The table near the bottle is hidden (no surfel within 60 cm) and a neighbour's face, tilted 30
// degrees, lies beside it: no surfel near the object shows its support. The up is still the
// table's (the scene's support), neither the face's nor the cameras' mean up (22 degrees off
// here: what the frame fell back to before the scene's up).
TEST(ObjectFrame, UpIsTheScenesSupportNotANeighboursTiltedFace) {
  PartialObject scene = MakePartialObject(Bottle(), 4000, 3);
  std::vector<uint32_t> keep, labels;
  for (uint32_t g = 0; g < scene.cloud.size(); ++g) {
    const Eigen::Vector3f p(&scene.cloud.positions[3 * g]);
    if (scene.labels[g] == 0 && Eigen::Vector2f(p.x(), p.y()).norm() < 0.6f) continue;
    keep.push_back(g);
    labels.push_back(scene.labels[g]);
  }
  GaussianCloud cloud = scene.cloud.Subset(keep);
  TriangleMesh face = MakeRectangle(0.2f, 0.2f, 4, 4);
  const Eigen::Matrix3f tilt = Eigen::AngleAxisf(30 * kPi / 180, Eigen::Vector3f::UnitX()).matrix();
  for (Eigen::Vector3f& v : face.vertices) v = tilt * v + Eigen::Vector3f(0.16f, 0, 0.02f);
  std::mt19937_64 rng(4);
  AppendSurfels(face, 1500, Appearance{}, SurfelSampling{}, rng, &cloud);
  labels.resize(cloud.size(), 0);
  auto split = SplitInstance(labels, 1, 50);
  ASSERT_TRUE(split.ok());
  const ObjectFrame frame = ComputeObjectFrame(cloud, *split, scene.cameras);
  EXPECT_GT(frame.up.z(), std::cos(2 * kPi / 180)) << frame.up.transpose();
}

// The frame of a partly seen bottle (instance 1) beside `count` surfels of `surface` labelled
// `label`.
ObjectFrame BottleFrameBeside(const TriangleMesh& surface, size_t count, uint32_t label,
                              size_t bottle_count, uint64_t seed) {
  PartialObject scene = MakePartialObject(Bottle(), bottle_count, 3);
  std::mt19937_64 rng(seed);
  AppendSurfels(surface, count, Appearance{}, SurfelSampling{}, rng, &scene.cloud);
  scene.labels.resize(scene.cloud.size(), label);
  auto split = SplitInstance(scene.labels, 1, 50);
  EXPECT_TRUE(split.ok());
  return split.ok() ? ComputeObjectFrame(scene.cloud, *split, scene.cameras) : ObjectFrame{};
}

// A low block's top slanted 7 degrees 14.5-29.5 cm from a bottle's axis (most of it within two of
// the bottle's radii, 27 cm: about its half-height; beyond twice its horizontal radius, 10-12 cm),
// with more surfels than the table shows there: the bottle's support is still the table. With the
// radius as the reach and a 10-degree mode the two mixed and the up came out 5 degrees off (as seed
// 44's touching bottles were tilted; RESULTS.md "Object frames: the object's own footprint").
TEST(ObjectFrame, ANeighboursSlantedTopBeyondTheFootprintDoesNotTiltTheUp) {
  TriangleMesh top = MakeRectangle(0.15f, 0.15f, 4, 4);
  const Eigen::Matrix3f tilt = Eigen::AngleAxisf(7 * kPi / 180, Eigen::Vector3f::UnitY()).matrix();
  for (Eigen::Vector3f& v : top.vertices) v = tilt * v + Eigen::Vector3f(-0.22f, 0, 0.004f);
  const ObjectFrame frame = BottleFrameBeside(top, 2500, 0, 4000, 5);
  EXPECT_GT(frame.up.z(), std::cos(0.5f * kPi / 180)) << frame.up.transpose();
}

// A neighbour's inner floor (a bowl's, 6 mm above the table, labelled 2) dense beside the bottle:
// more surfels per bin than a quarter of the table's around it, and higher. The support surrounds
// the object; the floor lies to one side.
// The support height found beside (or under) a square floor of `side` centred at `at`, 800 of
// its surfels labelled `label`, and a bottle of `bottle_count` surfels; NaN without a support.
float SupportWithAFloor(float side, const Eigen::Vector3f& at, uint32_t label,
                        size_t bottle_count) {
  TriangleMesh floor = MakeRectangle(side, side, 2, 2);
  for (Eigen::Vector3f& v : floor.vertices) v += at;
  const ObjectFrame frame = BottleFrameBeside(floor, 800, label, bottle_count, 7);
  return frame.has_support ? frame.support_height : std::numeric_limits<float>::quiet_NaN();
}

TEST(ObjectFrame, TheSupportSurroundsTheObjectNotANeighboursFloorBesideIt) {
  EXPECT_NEAR(SupportWithAFloor(0.06f, Eigen::Vector3f(0.12f, 0.0f, 0.006f), 2, 12000), 0.0f,
              0.002f);
}

// The object's own inner floor (a mug's, 5 mm above the table, that the segmentation left out
// of the instance: label 0) inside its footprint, around its centre: it surrounds the centre in
// every sector, dense and higher than the table. The support surrounds the object outside its
// footprint (seed 51's mug_7 stood on its own floor, 5.6 mm too short).
TEST(ObjectFrame, TheSupportIsNotTheObjectsOwnFloor) {
  EXPECT_NEAR(SupportWithAFloor(0.04f, Eigen::Vector3f(0.0f, 0.0f, 0.005f), 0, 4000), 0.0f, 0.002f);
}

TEST(Symmetry, RecoversTheAxisOfAPartlySeenBottle) {
  // 10-70 % occlusion: cameras over 140, 100 and 60 degrees of azimuth.
  for (double half_angle : {70.0, 50.0, 30.0}) {
    const Detected d = Detect(MakePartialObject(Bottle(), 4000, 5, half_angle));
    const SymmetryHypothesis* axis = nullptr;
    for (const SymmetryHypothesis& h : d.hypotheses) {
      if (h.kind == SymmetryKind::kAxis) axis = &h;
    }
    ASSERT_NE(axis, nullptr);
    EXPECT_TRUE(axis->accepted) << half_angle << ": " << axis->Describe();
    EXPECT_GT(axis->direction.z(), std::cos(2 * kPi / 180)) << axis->Describe();
    // The true axis is the z axis through the origin.
    EXPECT_LT(Eigen::Vector2f(axis->point.x(), axis->point.y()).norm(), 0.004f) << axis->Describe();
  }
}

// A mug's handle pulls the circle fit towards itself, and agreement (images within the match
// distance) is flat over millimetres; the alignment cost places the axis on the body's.
TEST(Symmetry, AMugsAxisIsTheBodysNotPulledByTheHandle) {
  ShapeSpec spec;
  spec.kind = ShapeKind::kMug;
  spec.size = {0.05f, 0, 0.1f};
  for (uint64_t seed : {11u, 12u, 13u, 14u}) {
    const PartialObject scene = MakePartialObject(MakeShapeMesh(spec, 48), 4000, seed, 100);
    auto offset = [&](bool refine) {
      SymmetryOptions options;
      options.refine_axis = refine;
      for (const SymmetryHypothesis& h : Detect(scene, options).hypotheses) {
        if (h.kind == SymmetryKind::kAxis) return Eigen::Vector2f(h.point.x(), h.point.y()).norm();
      }
      return 1.0f;
    };
    // The body's axis is the z axis: 4.0-4.3 mm off by agreement alone, 0.6-1.1 mm refined.
    EXPECT_GT(offset(false), 0.003f) << seed;
    EXPECT_LT(offset(true), 0.0015f) << seed;
  }
}

// A box turned by anything but its own turns puts its corners into space the views saw empty: its
// axis is n-fold (4 for a square footprint, 2 for a rectangle, also a nearly square one whose
// quarter turns overhang by less than the match distance) through its centre, not a solid of
// revolution; a bottle's stays continuous.
TEST(Symmetry, ABoxHasAnNFoldAxisThroughItsCentre) {
  const Eigen::Matrix3d yaw = Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitZ()).matrix();
  for (const auto& [size, order] : std::vector<std::pair<Eigen::Vector3f, int>>{
           {{0.14f, 0.14f, 0.07f}, 4}, {{0.11f, 0.075f, 0.14f}, 2}, {{0.083f, 0.096f, 0.16f}, 2}}) {
    ShapeSpec spec;
    spec.kind = ShapeKind::kBox;
    spec.size = size;
    TriangleMesh box = MakeShapeMesh(spec);
    box.Transform({yaw, Eigen::Vector3d::Zero()});
    const Detected d = Detect(MakePartialObject(box, 5000, 9));
    const SymmetryHypothesis* axis = nullptr;
    for (const SymmetryHypothesis& h : d.hypotheses) {
      if (h.kind == SymmetryKind::kAxis) axis = &h;
    }
    ASSERT_NE(axis, nullptr);
    EXPECT_EQ(axis->order, order) << axis->Describe();
    EXPECT_EQ(axis->copies, order - 1);
    EXPECT_TRUE(axis->accepted) << axis->Describe();
    EXPECT_LT(Eigen::Vector2f(axis->point.x(), axis->point.y()).norm(), 0.004f) << axis->Describe();
  }
  const Detected bottle = Detect(MakePartialObject(Bottle(), 4000, 5));
  for (const SymmetryHypothesis& h : bottle.hypotheses) {
    if (h.kind == SymmetryKind::kAxis) {
      EXPECT_EQ(h.order, 0) << h.Describe();
    }
  }
}

// A continuous axis must agree at every turn. Seed 44's box_7 (301 surfels, a third of them
// labelled, seen in few views): 11 of 16 decided images of its 270-degree turn agree, its whole
// 94.9 % over 234 decided, so the whole alone accepted a revolution and its completion stood 5-13
// mm off the box in space views saw empty. A mug's handle costs every turn alike (89 %), and a turn
// decided for a few images only says too little.
// A vertical axis scored at 11 turns of 30 degrees: agree / decided images per turn.
SymmetryHypothesis AxisScoredPerTurn(const std::vector<int>& agree,
                                     const std::vector<int>& decided) {
  SymmetryHypothesis axis;
  axis.kind = SymmetryKind::kAxis;
  axis.copies = 11;
  axis.copy_agree = agree;
  for (int k = 0; k < 11; ++k) axis.copy_contradict.push_back(decided[k] - agree[k]);
  return axis;
}

TEST(Symmetry, ASolidOfRevolutionAgreesAtEveryTurn) {
  const SymmetryHypothesis box = AxisScoredPerTurn({52, 17, 11, 14, 15, 9, 17, 15, 11, 14, 47},
                                                   {54, 18, 12, 14, 15, 9, 17, 15, 16, 17, 47});
  const SymmetryOptions options;
  EXPECT_FALSE(AgreesAtEveryTurn(box, options));
  SymmetryHypothesis mug = box;
  mug.copy_agree.assign(11, 267);
  mug.copy_contradict.assign(11, 33);  // 89 % at every turn
  EXPECT_TRUE(AgreesAtEveryTurn(mug, options));
  SymmetryHypothesis sparse = mug;
  sparse.copy_agree[4] = 2;
  sparse.copy_contradict[4] = 7;  // 9 images decided: too few to reject
  EXPECT_TRUE(AgreesAtEveryTurn(sparse, options));
  sparse.copy_contradict[4] = 8;  // 10
  EXPECT_FALSE(AgreesAtEveryTurn(sparse, options));
}

// A rectangular box with a third of its surfels unlabelled (mask noise, seed 85): per turn of 30
// degrees, agree / decided as scored there. Its third turns (120 and 240 degrees) agree 0.89 /
// 0.88 and the other turns on the whole 0.69, so it passed as 3-fold and was completed as a
// six-sided block 12 % too wide; its half turn agrees 0.99, better than either: 2-fold.
TEST(Symmetry, AnNFoldAxisAgreesBetterThanEveryOtherTurn) {
  SymmetryHypothesis box =
      AxisScoredPerTurn({220, 150, 81, 214, 155, 191, 154, 195, 87, 165, 237},
                        {314, 272, 185, 241, 168, 193, 197, 221, 170, 261, 339});
  box.scored = 300;
  SymmetryOptions options;
  EXPECT_EQ(DiscreteOrder(box, options), 2);
  options.order_outagrees_other_turns = false;
  EXPECT_EQ(DiscreteOrder(box, options), 3);
  SymmetryHypothesis square = box;  // quarter turns agree 0.98, the others 0.5
  for (int k = 0; k < 11; ++k) {
    square.copy_agree[k] = (k + 1) % 3 == 0 ? 196 : 100;
    square.copy_contradict[k] = 200 - square.copy_agree[k];
  }
  EXPECT_EQ(DiscreteOrder(square, SymmetryOptions{}), 4);
}

// A box turned by 17.19 degrees: the plane grid's 5-degree steps leave its best mirror plane 2.2
// or 2.8 degrees off (a mirror doubles that: a far face lands millimetres beside itself); the
// refinement by the alignment cost finds the box's own planes within a degree, through its centre.
TEST(Symmetry, MirrorPlanesAreRefinedBetweenTheGridsSteps) {
  const double yaw_rad = 0.3;
  const Eigen::Matrix3d yaw = Eigen::AngleAxisd(yaw_rad, Eigen::Vector3d::UnitZ()).matrix();
  for (const Eigen::Vector3f& size :
       {Eigen::Vector3f(0.14f, 0.09f, 0.07f), Eigen::Vector3f(0.11f, 0.075f, 0.14f)}) {
    ShapeSpec spec;
    spec.kind = ShapeKind::kBox;
    spec.size = size;
    TriangleMesh box = MakeShapeMesh(spec);
    box.Transform({yaw, Eigen::Vector3d::Zero()});
    const PartialObject scene = MakePartialObject(box, 5000, 9);
    // Degrees between a plane's normal and the nearer of the box's two face normals.
    auto angle_error = [&](const SymmetryHypothesis& h) {
      double best = 180;
      for (double face : {yaw_rad, yaw_rad + kPi / 2}) {
        const double c =
            std::abs(h.direction.x() * std::cos(face) + h.direction.y() * std::sin(face));
        best = std::min(best, std::acos(std::min(1.0, c)) * 180 / kPi);
      }
      return best;
    };
    SymmetryOptions grid_only;
    grid_only.refine_steps = 0;
    for (const auto& [options, max_error, min_error] :
         std::vector<std::tuple<SymmetryOptions, double, double>>{{grid_only, 3.0, 2.0},
                                                                  {SymmetryOptions{}, 1.0, 0.0}}) {
      const Detected d = Detect(scene, options);
      const SymmetryHypothesis* plane = nullptr;
      for (const SymmetryHypothesis& h : d.hypotheses) {
        if (h.kind == SymmetryKind::kPlane) plane = &h;
      }
      ASSERT_NE(plane, nullptr);
      EXPECT_TRUE(plane->accepted) << plane->Describe();
      EXPECT_LT(angle_error(*plane), max_error) << plane->Describe();
      EXPECT_GE(angle_error(*plane), min_error) << plane->Describe();
      // The box's centre (the origin) lies on its planes.
      EXPECT_LT(std::abs(plane->point.dot(plane->direction)), 0.002f) << plane->Describe();
    }
  }
}

// The synthetic generator's L-block (a tall bar, a lower arm at one end) with its arm towards
// views that cover only 70 degrees in front of it: the space behind the bar is seen by none.
PartialObject LBlockArmTowardsTheViews() {
  ShapeSpec spec;
  spec.kind = ShapeKind::kLBlock;
  spec.size = {0.146f, 0.089f, 0.135f};
  TriangleMesh mesh = MakeShapeMesh(spec);
  Rigid3d turn;
  turn.rotation = Eigen::AngleAxisd(-100 * kPi / 180, Eigen::Vector3d::UnitZ()).matrix();
  mesh.Transform(turn);
  return MakePartialObject(mesh, 5000, 7, 35);
}

// The bar's mid-plane maps the arm behind the bar, where no view looked: nothing contradicts it
// there, and the plane agrees 0.906. Mirror-symmetric shapes agree 0.95 and more; a plane needing
// 0.93 (`min_plane_agreement`) is not accepted, one needing the default 0.85 is.
TEST(Symmetry, AStricterPlaneAgreementRejectsABodySymmetricButForAPart) {
  const PartialObject scene = LBlockArmTowardsTheViews();
  const Detected d = Detect(scene);
  const auto plane =
      std::find_if(d.hypotheses.begin(), d.hypotheses.end(),
                   [](const SymmetryHypothesis& h) { return h.kind == SymmetryKind::kPlane; });
  ASSERT_NE(plane, d.hypotheses.end());
  EXPECT_TRUE(plane->accepted) << plane->Describe();
  EXPECT_LT(plane->agreement, 0.93) << plane->Describe();
  SymmetryOptions strict;
  strict.min_plane_agreement = 0.93;
  for (const SymmetryHypothesis& h : Detect(scene, strict).hypotheses) {
    EXPECT_FALSE(h.accepted) << h.Describe();
  }
}

// The stage's thresholds reach the prior: the completion of the L-block above mirrors the arm
// with the defaults and abstains when a plane needs 0.93.
TEST(CompleteStage, SymmetryThresholdsReachTheGeometricPrior) {
  auto decoded = CompleteCodec().Decode({{"min_plane_agreement", 0.93}, {"mesh_size", 64}});
  ASSERT_TRUE(decoded.ok()) << decoded.status();
  const CompletionOptions strict = ToCompletionOptions(*decoded);
  EXPECT_EQ(strict.geometric.symmetry.min_plane_agreement, 0.93);
  EXPECT_EQ(strict.geometric.symmetry.min_agreement, 0.85);
  CompletionOptions lenient = strict;
  lenient.geometric.symmetry.min_plane_agreement = CompleteStageOptions{}.min_plane_agreement;
  const PartialObject scene = LBlockArmTowardsTheViews();
  auto abstained = CompleteObject(scene.cameras, scene.cloud, scene.labels, 1, strict);
  auto mirrored = CompleteObject(scene.cameras, scene.cloud, scene.labels, 1, lenient);
  ASSERT_TRUE(abstained.ok() && mirrored.ok());
  EXPECT_TRUE(abstained->prior.abstained) << abstained->prior.reason;
  EXPECT_FALSE(mirrored->prior.abstained) << mirrored->prior.reason;
  EXPECT_GT(mirrored->object.size(), abstained->object.size());
}

TEST(Symmetry, ClaimsNoSymmetryOfAnAsymmetricBlock) {
  const Detected d = Detect(MakePartialObject(LBlock(), 5000, 7));
  ASSERT_FALSE(d.hypotheses.empty());
  for (const SymmetryHypothesis& h : d.hypotheses) {
    EXPECT_FALSE(h.accepted) << h.Describe();
  }
}

TEST(Completion, CompletesAPartlySeenBottleWithinTheFreeSpace) {
  const PartialObject scene = MakePartialObject(Bottle(), 4000, 11);
  CompletionOptions options;
  options.meshing.size_px = 96;
  auto done = CompleteObject(scene.cameras, scene.cloud, scene.labels, 1, options);
  ASSERT_TRUE(done.ok()) << done.status();
  const ExtraChannel* provenance = done->object.FindExtra(kProvenanceChannel);
  ASSERT_NE(provenance, nullptr);
  size_t completed = 0;
  for (float v : provenance->values) completed += v == 1.0f;
  EXPECT_EQ(completed, done->object.size() - done->raw.size());
  EXPECT_GT(completed, done->raw.size() / 4);  // the back half and the underside
  EXPECT_FALSE(done->prior.abstained);
  // The completed surfels lie on the bottle: within 3 mm of the true surface (radius 5 cm).
  const TriangleMesh truth = Bottle();
  auto truth_caster = RayCaster::Create(truth);
  ASSERT_TRUE(truth_caster.ok());
  auto volume = VoxelizeByRayParity(truth, truth.Bounds(), 8);
  ASSERT_TRUE(volume.ok());
  size_t far = 0;
  for (size_t g = done->raw.size(); g < done->object.size(); ++g) {
    const Eigen::Vector3f p(&done->object.positions[3 * g]);
    const float r = Eigen::Vector2f(p.x(), p.y()).norm();
    (void)r;
    // Distance to the mesh along the radial direction in both senses.
    const Eigen::Vector3f radial = Eigen::Vector3f(p.x(), p.y(), 0).normalized();
    const RayHit out = (*truth_caster)->Cast(p, radial);
    const RayHit in = (*truth_caster)->Cast(p, -radial);
    const float d = std::min(out.hit ? out.distance : 1.0f, in.hit ? in.distance : 1.0f);
    far += d > 0.003f && std::abs(p.z()) > 0.003f;  // cap surfels sit on z = 0
  }
  EXPECT_LT(far, completed / 10);
  EXPECT_TRUE(done->manifest["mesh"]["closed"].get<bool>());
  EXPECT_EQ(done->manifest["format"], kObjectFormat);
}

// A sphere seen from above and in front: the rotation axis is accepted, and the axis cap closes
// the open lower ring of its revolved surface (a ray from the centre straight down meets a
// surfel), inside the true sphere; without the cap the ray escapes through the underside.
TEST(GeometricPrior, TheAxisCapClosesTheLowerRingOfARevolvedSurface) {
  ShapeSpec spec;
  spec.kind = ShapeKind::kSphere;
  spec.size = {0.08f, 0, 0};  // centred at (0, 0, 0.08), resting on the table
  const PartialObject scene = MakePartialObject(MakeShapeMesh(spec, 48), 3000, 5);
  const PriorFixture fixture(scene);
  ASSERT_TRUE(fixture.ok());
  const PriorInput& input = fixture.input;
  const GaussianCloud& instance = fixture.instance;
  const Eigen::Vector3f centre(0, 0, 0.08f);
  auto closed_below = [&](const PriorOutput& out) {
    auto discs = [](const GaussianCloud& cloud) {
      std::vector<uint32_t> ids(cloud.size());
      for (uint32_t g = 0; g < ids.size(); ++g) ids[g] = g;
      return SurfelDiscs(cloud, ids, SurfelDiscOptions{});
    };
    TriangleMesh object = discs(instance);
    object.Append(discs(out.added));
    auto caster = RayCaster::Create(object);
    EXPECT_TRUE(caster.ok());
    return (*caster)->Cast(centre, -Eigen::Vector3f::UnitZ()).hit;
  };
  GeometricPriorOptions with_cap;
  with_cap.support_cap = false;  // the axis cap alone (support walls would make a skirt)
  auto capped = GeometricPrior(with_cap).Complete(input);
  ASSERT_TRUE(capped.ok()) << capped.status();
  ASSERT_GT(capped->report["added_by"].value("axis_cap", 0), 0) << capped->report.dump();
  EXPECT_TRUE(closed_below(*capped));
  for (size_t g = 0; g < capped->added.size(); ++g) {
    const Eigen::Vector3f p(&capped->added.positions[3 * g]);
    EXPECT_LT((p - centre).norm(), 0.08f + 0.005f) << g;
  }
  GeometricPriorOptions without_cap = with_cap;
  without_cap.axis_cap = false;
  auto open = GeometricPrior(without_cap).Complete(input);
  ASSERT_TRUE(open.ok()) << open.status();
  EXPECT_FALSE(closed_below(*open));
}

// A torus lying on the table, its hole seen through from the cameras: the axis is accepted, but
// the axis cap does not close the hole (no surface of the torus lies above it).
TEST(GeometricPrior, TheAxisCapLeavesATorusHoleOpen) {
  ShapeSpec spec;
  spec.kind = ShapeKind::kTorus;
  spec.size = {0.08f, 0.025f, 0};
  const PartialObject scene = MakePartialObject(MakeShapeMesh(spec, 48), 4000, 7);
  const PriorFixture fixture(scene);
  ASSERT_TRUE(fixture.ok());
  const PriorInput& input = fixture.input;
  GeometricPriorOptions options;
  options.support_cap = false;
  auto out = GeometricPrior(options).Complete(input);
  ASSERT_TRUE(out.ok()) << out.status();
  ASSERT_GT(out->report["added_by"].value("revolved", 0), 0) << out->report.dump();
  size_t in_hole = 0;
  for (size_t g = 0; g < out->added.size(); ++g) {
    const Eigen::Vector3f p(&out->added.positions[3 * g]);
    in_hole += Eigen::Vector2f(p.x(), p.y()).norm() < 0.08f - 0.025f - 0.01f;
  }
  EXPECT_EQ(in_hole, 0u) << out->report.dump();
  EXPECT_GT(out->report["rejected"].value("axis_cap_open_above", 0), 0);
}

// A mug (handle at +x) seen from the front: the body's axis is accepted with a mirror plane
// through it. The plane's turn about the axis rests on the handle alone; the handle lends it no
// images (they would stand centimetres beside the handle when the turn is a few degrees off), so
// nothing is added beyond the body's radius.
TEST(GeometricPrior, AMirrorPlaneThroughTheAxisLendsNoImagesOfTheHandle) {
  ShapeSpec spec;
  spec.kind = ShapeKind::kMug;
  spec.size = {0.05f, 0, 0.1f};
  for (uint64_t seed : {11u, 12u, 13u}) {
    const PartialObject scene = MakePartialObject(MakeShapeMesh(spec, 48), 4000, seed, 100);
    const PriorFixture fixture(scene);
    ASSERT_TRUE(fixture.ok());
    auto beyond_body = [&](bool skip) {
      GeometricPriorOptions options;
      options.support_cap = false;  // the cap fills the footprint, handle included
      options.mirror_skips_axis_asymmetric = skip;
      auto out = GeometricPrior(options).Complete(fixture.input);
      EXPECT_TRUE(out.ok()) << out.status();
      size_t count = 0;
      for (size_t g = 0; g < out->added.size(); ++g) {
        const Eigen::Vector3f p(&out->added.positions[3 * g]);
        count += Eigen::Vector2f(p.x(), p.y()).norm() > 0.05f + 0.01f;
      }
      return count;
    };
    // Planes a few degrees off the handle's: 9-18 surfels a centimetre or more beyond the body
    // when the handle is mirrored, 0 when not (0-7, revolved and mirrored images of the body's
    // rim, with the handle of before 2026-12-06 that hung into the cavity).
    const size_t mirrored = beyond_body(false), skipped = beyond_body(true);
    EXPECT_GE(mirrored, 8u) << seed;
    EXPECT_LT(2 * skipped, mirrored) << seed;
  }
}

// A mug among neighbours (the synthetic `small` scene of seed 143, half its objects asymmetric,
// never-seen surfels dropped), completed from its true labels: near the table, between its
// neighbours, no view saw the space its handle's lower end revolves into, so the body's axis held
// for that end; revolved, walled and capped, it made a ring about 12 cm across around a mug 7 cm
// wide, and it lifted the body's profile so the rest of the handle left as a neighbour's. As part
// of the handle (the part the axis does not hold for) it lends no images and stays the mug's.
TEST(GeometricPrior, AHandlesLowerEndIsTheHandles) {
  ClutterOptions clutter = *ClutterPreset("small");
  clutter.seed = 143;
  clutter.asymmetric_share = 0.5f;
  absl::StatusOr<ClutterScene> scene = GenerateClutterScene(clutter);
  ASSERT_TRUE(scene.ok()) << scene.status();
  ASSERT_TRUE(DropUnseenSurfels(&*scene).ok());
  const auto mug =
      std::find_if(scene->objects.begin(), scene->objects.end(),
                   [](const SynthObject& o) { return o.shape.kind == ShapeKind::kMug; });
  ASSERT_NE(mug, scene->objects.end());
  const Eigen::AlignedBox3f truth = mug->mesh.Bounds();
  const std::vector<uint32_t> labels(scene->instance_ids.begin(), scene->instance_ids.end());
  auto outside = [&](bool handle_joins_its_part, size_t* foreign) {
    CompletionOptions options;
    options.meshing.size_px = 64;
    options.geometric.handle_joins_its_part = handle_joins_its_part;
    auto done = CompleteObject(scene->cameras, scene->cloud, labels, mug->id, options);
    EXPECT_TRUE(done.ok()) << done.status();
    if (!done.ok()) return size_t{0};
    *foreign = done->prior.foreign.size();
    size_t count = 0;  // completed surfels more than 5 mm outside the true mug's box
    for (size_t g = done->raw.size(); g < done->object.size(); ++g) {
      const Eigen::Vector3f p(&done->object.positions[3 * g]);
      count += truth.exteriorDistance(p) > 0.005f;
    }
    return count;
  };
  size_t foreign_with = 0, foreign_without = 0;
  const size_t with = outside(true, &foreign_with), without = outside(false, &foreign_without);
  EXPECT_LE(with, 5u);
  EXPECT_LE(foreign_with, 10u);  // the handle stays the mug's
  EXPECT_GE(without, 50u);
  EXPECT_GE(foreign_without, 30u);
}

// A partly seen bottle (radius 5 cm) inside a tray's rim that hides the space around its base
// from every view, and three surfels of a neighbour, 1 cm beside its base, that the
// segmentation gave it: the last three of the instance.
const std::vector<Eigen::Vector3f> kStraysBesideTheBase = {Eigen::Vector3f(0.061f, 0.004f, 0.012f),
                                                           Eigen::Vector3f(0.060f, -0.006f, 0.018f),
                                                           Eigen::Vector3f(0.062f, 0.010f, 0.024f)};

PartialObject BottleWithANeighboursStrays(
    uint64_t seed, size_t count = 4000,
    const std::vector<Eigen::Vector3f>& targets = kStraysBesideTheBase) {
  PartialObject scene = MakePartialObject(Bottle(), count, seed);
  // A tray's rim around the base hides the space beside it from every view.
  ShapeSpec rim;
  rim.kind = ShapeKind::kCylinder;
  rim.size = {0.1f, 0, 0.06f};
  std::mt19937_64 rng(seed);
  AppendSurfels(MakeShapeMesh(rim, 48), 3000, Appearance{}, SurfelSampling{}, rng, &scene.cloud);
  scene.labels.resize(scene.cloud.size(), 0);
  // Copies of the bottle's surfel nearest each target, moved there (a neighbour's fragment).
  std::vector<uint32_t> keep(scene.cloud.size());
  std::iota(keep.begin(), keep.end(), 0u);
  for (const Eigen::Vector3f& target : targets) {
    uint32_t nearest = 0;
    float best = std::numeric_limits<float>::max();
    for (uint32_t g = 0; g < scene.cloud.size(); ++g) {
      const float d = (Eigen::Vector3f(&scene.cloud.positions[3 * g]) - target).norm();
      if (scene.labels[g] == 1 && d < best) best = d, nearest = g;
    }
    keep.push_back(nearest);
  }
  scene.cloud = scene.cloud.Subset(keep);
  for (size_t i = 0; i < targets.size(); ++i) {
    const size_t g = scene.labels.size() + i;
    for (int k = 0; k < 3; ++k) scene.cloud.positions[3 * g + k] = targets[i][k];
  }
  scene.labels.resize(scene.cloud.size(), 1);
  return scene;
}

// A partly seen bottle whose segmentation also holds three surfels of a neighbour, 1 cm
// beside its base, inside a tray's rim that hides the space around the base from every view
// (their images are not in seen-empty space, so the axis holds for them): revolved and mirrored
// they would ring the bottle's base. They lie beyond the body's profile at their height, lend
// the axis and the plane through it nothing, and are reported as not the bottle's (foreign).
TEST(GeometricPrior, ANeighboursSurfelsBesideTheBaseAreNotRevolvedIntoARing) {
  for (uint64_t seed : {21u, 22u, 23u}) {
    const PartialObject scene = BottleWithANeighboursStrays(seed);
    const float bottle_radius = 0.05f;
    const PriorFixture fixture(scene);
    ASSERT_TRUE(fixture.ok());
    auto ringed = [&](bool skip) {
      GeometricPriorOptions options;
      options.support_cap = false;  // the cap fills the footprint under the strays too
      options.skip_beyond_axis_profile = skip;
      auto out = GeometricPrior(options).Complete(fixture.input);
      EXPECT_TRUE(out.ok()) << out.status();
      size_t count = 0;
      for (size_t g = 0; g < out->added.size(); ++g) {
        const Eigen::Vector3f p(&out->added.positions[3 * g]);
        count += p.z() < 0.04f && Eigen::Vector2f(p.x(), p.y()).norm() > bottle_radius + 0.008f;
      }
      return count;
    };
    // 34-36 surfels of a ring beyond the base with the strays revolved and mirrored, 0 without.
    const size_t revolved = ringed(false), skipped = ringed(true);
    EXPECT_GE(revolved, 20u) << seed;
    EXPECT_LE(skipped, 2u) << seed;
    // And the strays, the last three of the instance, are found not to be the bottle's.
    auto out = GeometricPrior().Complete(fixture.input);
    ASSERT_TRUE(out.ok()) << out.status();
    const uint32_t n = static_cast<uint32_t>(fixture.instance.size());
    EXPECT_EQ(out->foreign, (std::vector<uint32_t>{n - 3, n - 2, n - 1})) << seed;
    EXPECT_EQ(out->report["foreign_observed"], 3) << seed;
  }
}

// Strays beside the base where the views saw the space around them (no tray's rim): their
// images lie in seen-empty space, as a handle's do, so the axis lends them nothing and keeps them;
// where a touching neighbour's label surrounds them, they are not the bottle's.
TEST(GeometricPrior, StraysANeighboursLabelSurroundsAreNotTheObjects) {
  // Seeds whose fitted axis holds for at least 70 % of the bottle (on others it is offset and
  // claims nothing beyond its profile: the guard of geometric_prior.h).
  for (uint64_t seed : {3u, 22u, 23u}) {
    PartialObject scene = MakePartialObject(Bottle(), 4000, seed);
    AppendObjectSurfelsAt(
        {Eigen::Vector3f(0.061f, 0.004f, 0.012f), Eigen::Vector3f(0.060f, -0.006f, 0.018f),
         Eigen::Vector3f(0.062f, 0.010f, 0.024f)},
        &scene);
    PriorFixture fixture(scene);
    ASSERT_TRUE(fixture.ok());
    const uint32_t n = static_cast<uint32_t>(fixture.instance.size());
    auto out = GeometricPrior().Complete(fixture.input);
    ASSERT_TRUE(out.ok()) << out.status();
    EXPECT_TRUE(out->foreign.empty()) << seed;  // a handle's case: kept
    std::vector<uint8_t> labelled(n, 0);
    labelled[n - 1] = labelled[n - 2] = labelled[n - 3] = 1;
    fixture.input.neighbour_labelled = &labelled;
    out = GeometricPrior().Complete(fixture.input);
    ASSERT_TRUE(out.ok()) << out.status();
    EXPECT_EQ(out->foreign, (std::vector<uint32_t>{n - 3, n - 2, n - 1})) << seed;
  }
}

// One surfel of a neighbour half a spacing beyond the bottle (radius 5 cm) near its base, inside
// the tray's rim (the axis holds for it) and surrounded by the neighbour's label: within the
// profile's one-spacing tolerance that every other surfel gets, so it stayed the bottle's and was
// revolved into a band half a spacing wide around it (seed 141's bottle_1, its extent 6 % too
// large). A surfel a neighbour's label surrounds gets no tolerance: it leaves the bottle.
TEST(GeometricPrior, ANeighboursSurfelWithinTheProfilesToleranceIsNotTheObjects) {
  for (uint64_t seed : {21u, 22u, 23u}) {
    float spacing = 0;
    {
      const PriorFixture plain(MakePartialObject(Bottle(), 4000, seed));
      ASSERT_TRUE(plain.ok());
      spacing = plain.input.frame.spacing;
    }
    const PartialObject scene = BottleWithANeighboursStrays(
        seed, 4000, {Eigen::Vector3f(0.05f + 0.5f * spacing, 0.0f, 0.018f)});
    PriorFixture fixture(scene);
    ASSERT_TRUE(fixture.ok());
    const uint32_t n = static_cast<uint32_t>(fixture.instance.size());
    std::vector<uint8_t> labelled(n, 0);
    labelled[n - 1] = 1;
    fixture.input.neighbour_labelled = &labelled;
    auto foreign = [&](float tolerance) {
      GeometricPriorOptions options;
      options.neighbour_profile_spacings = tolerance;
      auto out = GeometricPrior(options).Complete(fixture.input);
      EXPECT_TRUE(out.ok()) << out.status();
      return out.ok() ? out->foreign : std::vector<uint32_t>{};
    };
    EXPECT_EQ(foreign(0.0f), std::vector<uint32_t>{n - 1}) << seed;
    EXPECT_TRUE(foreign(1.0f).empty()) << seed;  // the tolerance every other surfel gets
  }
}

// Many of a neighbour's surfels at one height (30 at the contact, 6-7 mm beside the bottle,
// inside the tray's rim: the axis holds for them): a tenth of the profile's window, they lift its
// percentile over themselves and all stay (seed 53's bottle_2 kept two of six that way, its
// extent 8 % too large). A neighbour's label surrounds them, so they are not the profile's
// witnesses: all leave the bottle.
TEST(GeometricPrior, TheProfileIsTheBodysNotTheNeighboursItJudges) {
  std::vector<Eigen::Vector3f> crowd;
  for (int k = 0; k < 30; ++k) {
    const float angle = 0.015f * static_cast<float>(k % 10 - 5);
    const float radius = 0.056f + 0.0005f * static_cast<float>(k % 3);
    crowd.emplace_back(radius * std::cos(angle), radius * std::sin(angle),
                       0.014f + 0.003f * static_cast<float>(k / 10));
  }
  for (uint64_t seed : {21u, 22u, 23u}) {
    const PartialObject scene = BottleWithANeighboursStrays(seed, 4000, crowd);
    PriorFixture fixture(scene);
    ASSERT_TRUE(fixture.ok());
    const uint32_t n = static_cast<uint32_t>(fixture.instance.size());
    std::vector<uint8_t> labelled(n, 0);
    for (uint32_t k = 0; k < crowd.size(); ++k) labelled[n - 1 - k] = 1;
    fixture.input.neighbour_labelled = &labelled;
    auto foreign_crowd = [&](bool skip) {
      GeometricPriorOptions options;
      options.profile_skips_neighbour_labelled = skip;
      options.neighbour_profile_spacings = 1.0f;  // this rule alone, with the old tolerance
      auto out = GeometricPrior(options).Complete(fixture.input);
      EXPECT_TRUE(out.ok()) << out.status();
      return out.ok() ? std::count_if(out->foreign.begin(), out->foreign.end(),
                                      [&](uint32_t g) { return g + crowd.size() >= n; })
                      : 0;
    };
    EXPECT_EQ(foreign_crowd(true), 30) << seed;
    EXPECT_LT(foreign_crowd(false), 15) << seed;
  }
}

// A touching neighbour's patch at the contact (a 5 x 5 sheet of its surfels, 2.5 mm apart, 8-9
// mm beside a partly seen bottle, where the views saw the space around it): a neighbour's label
// surrounds only the patch's rim, the instance's own label its inner part. The rim leaves the
// bottle by the neighbour-label rule; the inner part, beyond the profile and joined to the rim,
// leaves with it (seed 51's bottle_2 kept 12 of a neighbour's surfels that way, its extent 13 %
// too large; RESULTS.md "Neighbours' surfels at the contact"); without the patch rule it stays.
TEST(GeometricPrior, ANeighboursPatchAtTheContactLeavesWhole) {
  for (uint64_t seed : {3u, 22u, 23u}) {
    PartialObject scene = MakePartialObject(Bottle(), 4000, seed);
    std::vector<Eigen::Vector3f> patch;
    for (int i = -2; i <= 2; ++i) {
      for (int j = -2; j <= 2; ++j) {
        const float y = 0.0025f * static_cast<float>(i);
        patch.emplace_back(0.058f + 10.0f * y * y, y, 0.10f + 0.0025f * static_cast<float>(j));
      }
    }
    AppendObjectSurfelsAt(patch, &scene);
    PriorFixture fixture(scene);
    ASSERT_TRUE(fixture.ok());
    const uint32_t n = static_cast<uint32_t>(fixture.instance.size());
    const uint32_t first = n - static_cast<uint32_t>(patch.size());
    std::vector<uint8_t> labelled(n, 0);
    std::vector<uint32_t> rim, whole;
    for (uint32_t k = 0; k < patch.size(); ++k) {
      const bool on_rim = k / 5 == 0 || k / 5 == 4 || k % 5 == 0 || k % 5 == 4;
      labelled[first + k] = on_rim;
      if (on_rim) rim.push_back(first + k);
      whole.push_back(first + k);
    }
    fixture.input.neighbour_labelled = &labelled;
    GeometricPriorOptions options;
    auto out = GeometricPrior(options).Complete(fixture.input);
    ASSERT_TRUE(out.ok()) << out.status();
    EXPECT_EQ(out->foreign, whole) << seed;
    options.drop_patches_beyond_axis_profile = false;
    out = GeometricPrior(options).Complete(fixture.input);
    ASSERT_TRUE(out.ok()) << out.status();
    EXPECT_EQ(out->foreign, rim) << seed;
  }
}

// The sources the accepted hypotheses lend no images (asymmetric), summed over them, by the grid
// alone and with the exact test agreeing; instance 1 of `scene` with a seen-through test.
std::pair<int, int> AsymmetricSources(const PartialObject& scene) {
  PriorFixture fixture(scene);
  EXPECT_TRUE(fixture.ok());
  if (!fixture.ok()) return {0, 0};
  auto seen = SeenThroughTest::Create(scene.cameras, scene.cloud, fixture.input.frame.radius,
                                      SeenThroughOptions{});
  EXPECT_TRUE(seen.ok()) << seen.status();
  if (!seen.ok()) return {0, 0};
  fixture.input.seen_through = &*seen;
  auto count = [&](bool exact) {
    GeometricPriorOptions options;
    options.exact_asymmetry = exact;
    auto out = GeometricPrior(options).Complete(fixture.input);
    EXPECT_TRUE(out.ok()) << out.status();
    return out.ok() ? out->report["asymmetric_sources"].get<int>() : 0;
  };
  return {count(false), count(true)};
}

// A thin bottle (3.5 cm radius, as the synthetic scenes' bottles): the free-space grid's voxels
// (4 radii / 64, 8 mm here) straddle its surface where the views graze the silhouette, so by the
// grid alone a quarter of its surfels have revolved or mirrored images in "seen-empty" space
// and lend nothing (an axis so contradicted also fails the 70 % guard of the profile rules). The
// exact test tells the surface from the space beside it; a mug's handle stays asymmetric.
// A box's n-fold axis has no profile (its radius varies around it), so the rule above goes by the
// body's reach instead: three surfels of a neighbour 9 mm past a box's corner that its label
// surrounds leave the box; unlabelled, they stay (seed 23's box_5 held six of bottle_7's surfels
// by its top corner, extent 10 % too large; RESULTS.md "Neighbours' surfels past a box's corner").
TEST(GeometricPrior, ANeighboursSurfelsPastABoxsCornerAreNotTheBoxs) {
  ShapeSpec spec;
  spec.kind = ShapeKind::kBox;
  spec.size = {0.11f, 0.075f, 0.14f};
  TriangleMesh box = MakeShapeMesh(spec);
  const Eigen::Matrix3d yaw = Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitZ()).matrix();
  box.Transform({yaw, Eigen::Vector3d::Zero()});
  // Views all round: the corner's image under the 2-fold axis is in space they saw empty.
  PartialObject scene = MakePartialObject(box, 5000, 9, 160);
  // The corner at local (+x, -y), pushed 9 mm further out along its diagonal.
  const Eigen::Vector3f corner = yaw.cast<float>() * Eigen::Vector3f(0.055f, -0.0375f, 0);
  const Eigen::Vector3f out = corner.normalized() * (corner.norm() + 0.009f);
  AppendObjectSurfelsAt({out + Eigen::Vector3f(0, 0, 0.10f), out + Eigen::Vector3f(0, 0, 0.11f),
                         out + Eigen::Vector3f(0, 0, 0.12f)},
                        &scene);
  PriorFixture fixture(scene);
  ASSERT_TRUE(fixture.ok());
  const uint32_t n = static_cast<uint32_t>(fixture.instance.size());
  auto completed = GeometricPrior().Complete(fixture.input);
  ASSERT_TRUE(completed.ok()) << completed.status();
  EXPECT_TRUE(completed->foreign.empty());
  EXPECT_TRUE(completed->report["hypotheses"].dump().find("2-fold axis") != std::string::npos)
      << completed->report["hypotheses"].dump();
  std::vector<uint8_t> labelled(n, 0);
  labelled[n - 1] = labelled[n - 2] = labelled[n - 3] = 1;
  fixture.input.neighbour_labelled = &labelled;
  completed = GeometricPrior().Complete(fixture.input);
  ASSERT_TRUE(completed.ok()) << completed.status();
  EXPECT_EQ(completed->foreign, (std::vector<uint32_t>{n - 3, n - 2, n - 1}));
}

TEST(GeometricPrior, AThinBottlesBodyIsSymmetricWhereViewsGrazeIt) {
  ShapeSpec bottle;
  bottle.kind = ShapeKind::kBottle;
  bottle.size = {0.035f, 0, 0.22f};
  for (uint64_t seed : {31u, 32u, 33u}) {
    // 2439 surfels: 575-624 by the grid, 0-1 with the exact test.
    const auto [grid, exact] =
        AsymmetricSources(MakePartialObject(MakeShapeMesh(bottle, 48), 3000, seed));
    EXPECT_GE(grid, 400) << seed;
    EXPECT_LE(exact, 10) << seed;
  }
  ShapeSpec mug;
  mug.kind = ShapeKind::kMug;
  mug.size = {0.05f, 0, 0.1f};
  for (uint64_t seed : {11u, 12u, 13u}) {
    // 3597 surfels, 308-316 of them the handle's: 318-398 by the grid, 292-367 with the exact
    // test (the axis's sources are the handle; the plane's a few more).
    const auto [grid, exact] =
        AsymmetricSources(MakePartialObject(MakeShapeMesh(mug, 48), 4000, seed, 100));
    EXPECT_GE(exact, 250) << seed;
    EXPECT_GE(exact, grid * 85 / 100) << seed;
  }
}

// The completion moves the surfels the prior found not to be the object's to the occluders: the
// observed part keeps the bottle and loses the neighbour's.
TEST(Completion, ANeighboursSurfelsLeaveTheObject) {
  // Sparser than the prior's test (the median spacing 7 mm): the strays are within the stray
  // removal's reach of the bottle, as they were in the scene where this was found.
  const PartialObject scene = BottleWithANeighboursStrays(21, 800);
  CompletionOptions options;
  options.meshing.size_px = 64;
  auto done = CompleteObject(scene.cameras, scene.cloud, scene.labels, 1, options);
  ASSERT_TRUE(done.ok()) << done.status();
  EXPECT_EQ(done->manifest["prior_report"]["foreign_observed"], 3);
  size_t labelled = 0, beside = 0;
  for (uint32_t l : scene.labels) labelled += l == 1;
  for (size_t g = 0; g < done->raw.size(); ++g) {
    const Eigen::Vector3f p(&done->raw.positions[3 * g]);
    beside += Eigen::Vector2f(p.x(), p.y()).norm() > 0.06f;
  }
  EXPECT_EQ(beside, 0u);
  EXPECT_EQ(done->raw.size() + done->stray_removed, labelled);
  EXPECT_GE(done->stray_removed, 3u);
}

// The joint refinement inside the completion: real views cropped and rendered in situ (their
// images here are renders of the scene itself), the ring's generated views; the object keeps its
// surfel count and provenance, and views without an image are skipped and counted.
TEST(Completion, RefinesWithRealAndGeneratedViews) {
  const PartialObject scene = MakePartialObject(Bottle(), 2500, 17);
  CompletionOptions options;
  options.meshing.size_px = 64;
  options.refinement.iterations = 30;
  int loads = 0;
  options.load_view = [&](int view) -> absl::StatusOr<Image> {
    ++loads;
    RenderOptions o;
    auto r = Render(scene.cloud, scene.cameras.at(view), o);
    if (!r.ok()) return r.status();
    return Image{r->width, r->height, 3, r->color};
  };
  auto done = CompleteObject(scene.cameras, scene.cloud, scene.labels, 1, options);
  ASSERT_TRUE(done.ok()) << done.status();
  const nlohmann::json& r = done->manifest["refinement"];
  EXPECT_EQ(r["status"], "done");
  EXPECT_EQ(r["iterations"], 30);
  EXPECT_EQ(r["generated_views"], 16);
  EXPECT_GT(r["real_views"].get<int>(), 0);
  EXPECT_EQ(r["real_views"].get<int>() + r["real_views_skipped"].get<int>(), loads);
  EXPECT_TRUE(std::isfinite(r["final_loss"].get<double>()));
  const ExtraChannel* provenance = done->object.FindExtra(kProvenanceChannel);
  ASSERT_NE(provenance, nullptr);
  EXPECT_EQ(provenance->values.size(), done->object.size());
  for (float v : done->object.positions) ASSERT_TRUE(std::isfinite(v));

  options.load_view = [](int) -> absl::StatusOr<Image> { return absl::NotFoundError("no image"); };
  auto no_images = CompleteObject(scene.cameras, scene.cloud, scene.labels, 1, options);
  ASSERT_TRUE(no_images.ok()) << no_images.status();
  EXPECT_EQ(no_images->manifest["refinement"]["real_views"], 0);
  EXPECT_GT(no_images->manifest["refinement"]["real_views_skipped"].get<int>(), 0);
  options.refinement.iterations = 0;
  auto off = CompleteObject(scene.cameras, scene.cloud, scene.labels, 1, options);
  ASSERT_TRUE(off.ok());
  EXPECT_EQ(off->manifest["refinement"]["status"], "not run");
}

// A partly seen bottle with a wall behind it (x = -0.12): the ring views from that side see it
// occluded, so they are unknown and become the diffusion sampler's targets.
PartialObject BottleBeforeAWall() {
  PartialObject scene = MakePartialObject(Bottle(), 2500, 19);
  TriangleMesh wall = MakeRectangle(0.6f, 0.5f, 6, 5);
  for (auto& v : wall.vertices) v = Eigen::Vector3f(-0.12f, v.x(), v.y() + 0.25f);
  std::mt19937_64 rng(3);
  AppendSurfels(wall, 3000, Appearance{}, SurfelSampling{}, rng, &scene.cloud);
  scene.labels.resize(scene.cloud.size(), 0);
  return scene;
}

// The analytic denoiser (data mean 0.2 under every condition view, 0 unconditional, stddev 0.4)
// behind a loopback Denoiser service that takes timesteps below `timesteps`.
class LoopbackAnalyticDenoiser {
 public:
  explicit LoopbackAnalyticDenoiser(int timesteps = 1000)
      : service_(&analytic_, "analytic-gaussian", {4, 32, 32}, timesteps) {
    rpc::ServerOptions options;
    options.listen = "127.0.0.1:0";
    auto server = rpc::Server::Start(options, {&service_}, {"instascene.v1.Denoiser"});
    EXPECT_TRUE(server.ok()) << server.status();
    if (server.ok()) server_ = std::move(*server);
  }
  ~LoopbackAnalyticDenoiser() {
    if (server_) server_->Drain(std::chrono::milliseconds(100));
  }
  bool ok() const { return server_ != nullptr; }
  std::string uri() const { return "grpc://" + server_->address(); }

 private:
  diffusion::AnalyticDenoiser analytic_{diffusion::NoiseSchedule::ScaledLinear(),
                                        std::vector<double>(16, 0.2), 0.0, 0.4};
  diffusion::DenoiserService service_;
  std::unique_ptr<rpc::Server> server_;
};

// The diffusion prior through a loopback Denoiser service (the analytic denoiser: it proves the
// plumbing, not the images): it generates one image per unknown ring view, which the refinement
// then fits; an unreachable or misbehaving denoiser fails the object with a message naming it.
TEST(Completion, DiffusionPriorThroughADenoiserService) {
  const LoopbackAnalyticDenoiser denoiser;
  ASSERT_TRUE(denoiser.ok());
  const PartialObject scene = BottleBeforeAWall();
  ASSERT_GT(std::count(scene.labels.begin(), scene.labels.end(), 0), 0);  // the wall is there
  CompletionOptions options;
  options.meshing.size_px = 64;
  options.prior = "diffusion";
  options.denoiser = denoiser.uri();
  options.refinement.iterations = 5;
  auto done = CompleteObject(scene.cameras, scene.cloud, scene.labels, 1, options);
  ASSERT_TRUE(done.ok()) << done.status();
  const int unknown = done->manifest["unknown_views"].get<int>();
  ASSERT_GT(unknown, 0);
  EXPECT_EQ(done->manifest["prior"], "diffusion");
  EXPECT_EQ(static_cast<int>(done->prior.generated.size()), unknown);
  for (const ViewImages& v : done->prior.generated) {
    EXPECT_EQ(v.rgb.size(), static_cast<size_t>(3) * v.camera.width * v.camera.height);
  }
  const int64_t warped = done->prior.report["warped_latent_pixels"].get<int64_t>();
  EXPECT_GT(warped, 0);
  // Depth and mask come from the latent's depth channel: in every warped cell the decoded depth
  // is the instance hit's along the latent grid's ray through the cell, exactly
  // (replacement runs to the last step); masked pixels have a depth, others none.
  auto mesh = RayCaster::Create(SurfelDiscs(done->raw, {}, SurfelDiscOptions{}));
  ASSERT_TRUE(mesh.ok());
  int64_t exact = 0, object_pixels = 0;
  for (const ViewImages& v : done->prior.generated) {
    const size_t pixels = static_cast<size_t>(v.camera.width) * v.camera.height;
    ASSERT_EQ(v.depth.size(), pixels);
    ASSERT_EQ(v.mask.size(), pixels);
    for (size_t i = 0; i < pixels; ++i) {
      EXPECT_EQ(v.mask[i] != 0, v.depth[i] > 0) << i;
      object_pixels += v.mask[i];
    }
    const int n = 32, step = v.camera.width / n;
    const PinholeCamera grid = v.camera.Scaled(static_cast<double>(n) / v.camera.width);
    const Eigen::Vector3f eye = v.camera.CenterInWorld().cast<float>();
    const Eigen::Vector3d axis = v.camera.camera_from_world.rotation.row(2).transpose();
    for (int cy = 0; cy < n; ++cy) {
      for (int cx = 0; cx < n; ++cx) {
        const int x = cx * step + step / 2, y = cy * step + step / 2;
        const Eigen::Vector3d dir = grid.PixelRayInWorld(cx, cy);
        const RayHit hit = (*mesh)->Cast(eye, dir.cast<float>());
        const size_t i = static_cast<size_t>(y) * v.camera.width + x;
        exact += hit.hit && v.mask[i] && std::abs(v.depth[i] - hit.distance * dir.dot(axis)) < 1e-4;
      }
    }
  }
  EXPECT_GE(exact, warped);
  EXPECT_EQ(done->prior.report["generated_object_pixels"].get<int64_t>(), object_pixels);
  // The unseen-region estimate (7.8) pins what the real views saw empty to the background and
  // leaves the rest (space behind the wall, the bottle's unseen side) to the sampler.
  EXPECT_EQ(done->prior.report["unseen_mask"], true);
  EXPECT_GT(done->prior.report["background_cells"].get<int64_t>(), 0);
  EXPECT_GT(done->prior.report["generated_cells"].get<int64_t>(), 0);
  EXPECT_EQ(done->manifest["refinement"]["generated_from"], "the prior's images");
  EXPECT_EQ(done->object.size(), done->raw.size());  // this prior adds images, not surfels

  options.denoiser = "grpc://127.0.0.1:1";  // nothing listens there
  auto unreachable = CompleteObject(scene.cameras, scene.cloud, scene.labels, 1, options);
  EXPECT_EQ(unreachable.status().code(), absl::StatusCode::kUnavailable);
  EXPECT_NE(unreachable.status().message().find("denoiser"), std::string::npos);
  const LoopbackAnalyticDenoiser wrong(10);  // refuses timesteps >= 10
  ASSERT_TRUE(wrong.ok());
  options.denoiser = wrong.uri();
  auto refused = CompleteObject(scene.cameras, scene.cloud, scene.labels, 1, options);
  EXPECT_EQ(refused.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(refused.status().message().find("timestep"), std::string::npos) << refused.status();
  options.denoiser = "onnx:absent/model.json";
  auto no_config = CompleteObject(scene.cameras, scene.cloud, scene.labels, 1, options);
  EXPECT_EQ(no_config.status().code(), absl::StatusCode::kNotFound);
  EXPECT_NE(no_config.status().message().find("absent/model.json"), std::string::npos);
}

// The replacement schedule and the warp space (ALGORITHM.md 7.7's open choices) as settings:
// replacing to the last step leaves the known cells exactly the warped known content; never
// replacing lets them drift; a pixel-space warp finds known cells too.
TEST(Completion, DiffusionReplacementScheduleAndWarpSpace) {
  const LoopbackAnalyticDenoiser denoiser;
  ASSERT_TRUE(denoiser.ok());
  const PartialObject scene = BottleBeforeAWall();
  CompletionOptions options;
  options.meshing.size_px = 64;
  options.prior = "diffusion";
  options.denoiser = denoiser.uri();
  auto run = [&](double fraction, const std::string& warp) {
    options.diffusion.replace_fraction = fraction;
    options.diffusion.warp = warp;
    return CompleteObject(scene.cameras, scene.cloud, scene.labels, 1, options);
  };
  auto every = run(1.0, "latent");
  ASSERT_TRUE(every.ok()) << every.status();
  ASSERT_GT(every->prior.report["warped_latent_pixels"].get<int64_t>(), 0);
  EXPECT_EQ(every->prior.report["known_cells_drift"].get<double>(), 0.0);
  auto never = run(0.0, "latent");
  ASSERT_TRUE(never.ok()) << never.status();
  EXPECT_GT(never->prior.report["known_cells_drift"].get<double>(), 0.05);
  auto half = run(0.5, "latent");
  ASSERT_TRUE(half.ok()) << half.status();
  EXPECT_GT(half->prior.report["known_cells_drift"].get<double>(), 0.0);
  EXPECT_EQ(half->prior.report["replace_fraction"].get<double>(), 0.5);
  auto pixel = run(1.0, "pixel");
  ASSERT_TRUE(pixel.ok()) << pixel.status();
  EXPECT_EQ(pixel->prior.report["warp"], "pixel");
  EXPECT_GT(pixel->prior.report["warped_latent_pixels"].get<int64_t>(), 0);
  EXPECT_EQ(pixel->prior.report["known_cells_drift"].get<double>(), 0.0);
  options.diffusion.unseen_mask = false;  // every cell not known is generated
  auto unmasked = run(1.0, "latent");
  ASSERT_TRUE(unmasked.ok()) << unmasked.status();
  EXPECT_EQ(unmasked->prior.report["unseen_mask"], false);
  EXPECT_EQ(unmasked->prior.report["background_cells"].get<int64_t>(), 0);
  EXPECT_GT(unmasked->prior.report["generated_cells"].get<int64_t>(),
            every->prior.report["generated_cells"].get<int64_t>());
  options.diffusion.unseen_mask = true;
  // The codec (VAE) interface: every known view encoded once (and the white background once),
  // every generated one decoded once.
  struct Counting : diffusion::LatentCodec {
    diffusion::IdentityCodec identity{32};
    mutable std::atomic<int> encoded{0}, decoded{0};
    std::string name() const override { return "counting identity"; }
    int latent_values() const override { return identity.latent_values(); }
    absl::StatusOr<std::vector<float>> Encode(const std::vector<float>& rgb, int w,
                                              int h) const override {
      ++encoded;
      return identity.Encode(rgb, w, h);
    }
    absl::StatusOr<std::vector<float>> Decode(const std::vector<float>& latent, int w,
                                              int h) const override {
      ++decoded;
      return identity.Decode(latent, w, h);
    }
  };
  auto counting = std::make_shared<Counting>();
  options.diffusion.codec = counting;
  auto coded = run(1.0, "latent");
  ASSERT_TRUE(coded.ok()) << coded.status();
  EXPECT_EQ(coded->prior.report["vae"], "counting identity");
  EXPECT_EQ(counting->encoded.load(),
            static_cast<int>(coded->ring.size()) + 1 - coded->manifest["unknown_views"].get<int>());
  EXPECT_EQ(counting->decoded.load(), coded->manifest["unknown_views"].get<int>());
  // A four-channel codec (a Stable Diffusion VAE's latent depth): the denoiser sees [5, 32, 32]
  // (MVD-Fusion's layout), both warps move all four channels.
  struct FourChannels : diffusion::LatentCodec {
    diffusion::IdentityCodec identity{32};
    std::string name() const override { return "identity + luminance"; }
    int latent_values() const override { return 4 * 32 * 32; }
    absl::StatusOr<std::vector<float>> Encode(const std::vector<float>& rgb, int w,
                                              int h) const override {
      absl::StatusOr<std::vector<float>> encoded = identity.Encode(rgb, w, h);
      if (!encoded.ok()) return encoded.status();
      std::vector<float> latent = std::move(*encoded);
      for (int cell = 0; cell < 32 * 32; ++cell)
        latent.push_back((latent[cell] + latent[1024 + cell] + latent[2048 + cell]) / 3);
      return latent;
    }
    absl::StatusOr<std::vector<float>> Decode(const std::vector<float>& latent, int w,
                                              int h) const override {
      return identity.Decode(std::vector<float>(latent.begin(), latent.begin() + 3 * 1024), w, h);
    }
  };
  options.diffusion.codec = std::make_shared<FourChannels>();
  for (const char* warp : {"latent", "pixel"}) {
    auto four = run(1.0, warp);
    ASSERT_TRUE(four.ok()) << four.status();
    EXPECT_EQ(four->prior.report["latent_shape"], nlohmann::json({5, 32, 32})) << warp;
    EXPECT_EQ(four->prior.report["known_cells_drift"].get<double>(), 0.0) << warp;
    EXPECT_GT(four->prior.report["warped_latent_pixels"].get<int64_t>(), 0) << warp;
  }
  options.diffusion.codec = std::make_shared<diffusion::IdentityCodec>(16);  // 3 x 16²: refused
  EXPECT_EQ(run(1.0, "latent").status().code(), absl::StatusCode::kInvalidArgument);
  options.diffusion.codec = nullptr;
  EXPECT_EQ(run(1.0, "voxel").status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(run(1.5, "latent").status().code(), absl::StatusCode::kInvalidArgument);
}

// The complete stage takes the denoiser from the worker's settings, never from the job.
TEST(CompleteStage, DiffusionNeedsAWorkerWithADenoiser) {
  const pipeline::StageDefinition stage = CompleteStage();
  pipeline::StageContext context;
  context.parameters = {{"prior", "diffusion"}};
  auto without = stage.run(context);
  EXPECT_EQ(without.status().code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_NE(without.status().message().find("--denoiser grpc://HOST:PORT"), std::string::npos);
  context.settings["denoiser"] = "grpc://127.0.0.1:1";
  auto with = stage.run(context);  // past the check: this context has no segment input
  EXPECT_NE(with.status().code(), absl::StatusCode::kFailedPrecondition) << with.status();
  EXPECT_NE(with.status().message().find("segment"), std::string::npos) << with.status();
}

TEST(Completion, ResultsDoNotDependOnThreadCount) {
  const PartialObject scene = MakePartialObject(Bottle(), 2500, 13);
  CompletionOptions options;
  options.meshing.size_px = 64;
  options.num_threads = 1;
  auto one = CompleteObject(scene.cameras, scene.cloud, scene.labels, 1, options);
  options.num_threads = 2;
  auto two = CompleteObject(scene.cameras, scene.cloud, scene.labels, 1, options);
  ASSERT_TRUE(one.ok() && two.ok());
  EXPECT_EQ(EncodeGaussianPly(one->object), EncodeGaussianPly(two->object));
  EXPECT_EQ(one->manifest.dump(), two->manifest.dump());
}

TEST(Completion, BadInstancesFailWithAMessage) {
  const PartialObject scene = MakePartialObject(Bottle(), 2500, 17);
  CompletionOptions options;
  auto empty = CompleteObject(scene.cameras, scene.cloud, scene.labels, 9, options);
  EXPECT_EQ(empty.status().code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_NE(empty.status().message().find("empty instance"), std::string::npos);
  std::vector<uint32_t> few = scene.labels;
  int kept = 0;
  for (uint32_t& l : few) {
    if (l == 1 && ++kept > 10) l = 0;
  }
  auto degenerate = CompleteObject(scene.cameras, scene.cloud, few, 1, options);
  EXPECT_EQ(degenerate.status().code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_NE(degenerate.status().message().find("degenerate"), std::string::npos);
  // An object no real view sees: every camera turned away.
  std::vector<PinholeCamera> away = scene.cameras;
  for (PinholeCamera& c : away) {
    c = OrbitCamera({0, 0, 5}, {0, 0, 1}, 1.0, 0, 10, 64, 48, 40);
    c.camera_from_world.rotation = -c.camera_from_world.rotation;
    c.camera_from_world.rotation.row(0) *= -1;  // keep it a rotation, looking away
  }
  auto unseen = CompleteObject(away, scene.cloud, scene.labels, 1, options);
  EXPECT_EQ(unseen.status().code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_NE(unseen.status().message().find("no real view"), std::string::npos);
  options.prior = "magic";
  EXPECT_EQ(CompleteObject(scene.cameras, scene.cloud, scene.labels, 1, options).status().code(),
            absl::StatusCode::kInvalidArgument);
  std::vector<uint32_t> short_labels(3, 1);
  EXPECT_EQ(CompleteObject(scene.cameras, scene.cloud, short_labels, 1, CompletionOptions{})
                .status()
                .code(),
            absl::StatusCode::kInvalidArgument);
}

TEST(MeshVolume, RayParityMatchesTheAnalyticVolume) {
  ShapeSpec spec;
  spec.kind = ShapeKind::kSphere;
  spec.size = {0.5f, 0, 0};
  const TriangleMesh sphere = MakeShapeMesh(spec, 64);
  Eigen::AlignedBox3f box = sphere.Bounds();
  box.extend(box.min() - Eigen::Vector3f::Constant(0.05f));
  box.extend(box.max() + Eigen::Vector3f::Constant(0.05f));
  auto voxels = VoxelizeByRayParity(sphere, box, 48);
  ASSERT_TRUE(voxels.ok());
  size_t inside = 0;
  for (uint8_t v : *voxels) inside += v;
  const double voxel_volume = box.sizes().prod() / (48.0 * 48 * 48);
  EXPECT_NEAR(inside * voxel_volume, 4.0 / 3.0 * kPi * 0.125, 0.03 * 4.0 / 3.0 * kPi * 0.125);
}

}  // namespace
}  // namespace instascene::generation
