#include "services/generation/testing/partial_objects.h"

#include <limits>
#include <numeric>
#include <random>

#include <gtest/gtest.h>

#include "common/geometry/point_index.h"
#include "common/geometry/rigid.h"
#include "common/mesh/surfel_mesh.h"
#include "common/synth/primitives.h"
#include "common/synth/surfels.h"

namespace instascene::generation::testing {

PartialObject MakePartialObject(const TriangleMesh& object_mesh, size_t count, uint64_t seed,
                                double front_half_angle_deg) {
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

PriorFixture::PriorFixture(const PartialObject& scene) {
  auto split = SplitInstance(scene.labels, 1, 50);
  EXPECT_TRUE(split.ok());
  if (!split.ok()) return;
  input.frame = ComputeObjectFrame(scene.cloud, *split, scene.cameras);
  space = CarveScene(scene, input.frame);
  instance = scene.cloud.Subset(split->instance);
  input.instance = &instance;
  if (space.grid.has_value()) input.free_space = &*space.grid;
}

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

Detected Detect(const PartialObject& scene, const SymmetryOptions& options) {
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
  // The observed surface as the prior builds it, without a seen-through test (normals turned
  // away from the frame's centre).
  const PointIndex3 index(points);
  const ObservedSurface surface(&index, normals, nullptr, d.frame.center, d.frame.spacing, {});
  d.hypotheses = DetectSymmetries(points, normals, d.frame, *space.grid, options, &surface);
  return d;
}

const std::vector<Eigen::Vector3f> kStraysBesideTheBase = {Eigen::Vector3f(0.061f, 0.004f, 0.012f),
                                                           Eigen::Vector3f(0.060f, -0.006f, 0.018f),
                                                           Eigen::Vector3f(0.062f, 0.010f, 0.024f)};

PartialObject BottleWithANeighboursStrays(uint64_t seed, size_t count,
                                          const std::vector<Eigen::Vector3f>& targets) {
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

}  // namespace instascene::generation::testing
