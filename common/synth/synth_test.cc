#include <gtest/gtest.h>

#include <map>
#include <numbers>

#include "common/raster/rasterizer.h"
#include "common/synth/cluttered_scene.h"
#include "common/synth/primitives.h"

namespace instascene {
namespace {

// Signed volume by the divergence theorem: positive and equal to the analytic volume for a
// closed, outward-oriented mesh.
double SignedVolume(const TriangleMesh& mesh) {
  double v = 0;
  for (const auto& t : mesh.triangles) {
    v += mesh.vertices[t[0]].cast<double>().dot(mesh.vertices[t[1]].cast<double>().cross(mesh.vertices[t[2]].cast<double>())) / 6.0;
  }
  return v;
}

TEST(Primitives, ClosedMeshesHaveTheAnalyticVolume) {
  const double pi = std::numbers::pi;
  EXPECT_NEAR(SignedVolume(MakeShapeMesh({ShapeKind::kBox, {0.2f, 0.3f, 0.4f}})), 0.024, 1e-6);
  EXPECT_NEAR(SignedVolume(MakeShapeMesh({ShapeKind::kCylinder, {0.1f, 0, 0.2f}}, 256)), pi * 0.01 * 0.2, 2e-5);
  EXPECT_NEAR(SignedVolume(MakeShapeMesh({ShapeKind::kCone, {0.1f, 0, 0.3f}}, 256)), pi * 0.01 * 0.1, 2e-5);
  EXPECT_NEAR(SignedVolume(MakeShapeMesh({ShapeKind::kSphere, {0.1f, 0, 0}}, 256)), 4.0 / 3 * pi * 1e-3, 2e-5);
  EXPECT_NEAR(SignedVolume(MakeShapeMesh({ShapeKind::kTorus, {0.1f, 0.03f, 0}}, 256)), 2 * pi * pi * 0.1 * 0.0009, 2e-5);
  for (ShapeKind k : {ShapeKind::kBottle, ShapeKind::kCup, ShapeKind::kBowl}) {
    const TriangleMesh m = MakeShapeMesh({k, {0.05f, 0, 0.15f}});
    EXPECT_GT(SignedVolume(m), 0.0) << ShapeKindName(k);
    EXPECT_NEAR(m.Bounds().min().z(), 0.0f, 1e-6f);
  }
}

TEST(ClutterScene, DeterministicWithGroundTruthIds) {
  absl::StatusOr<ClutterOptions> options = ClutterPreset("tiny");
  ASSERT_TRUE(options.ok());
  absl::StatusOr<ClutterScene> a = GenerateClutterScene(*options);
  absl::StatusOr<ClutterScene> b = GenerateClutterScene(*options);
  ASSERT_TRUE(a.ok() && b.ok()) << a.status();
  EXPECT_EQ(a->cloud.positions, b->cloud.positions);
  EXPECT_EQ(a->cloud.sh, b->cloud.sh);
  ASSERT_EQ(a->cloud.size(), options->gaussians);
  ASSERT_TRUE(a->cloud.Validate().ok());
  ASSERT_EQ(a->instance_ids.size(), a->cloud.size());
  ASSERT_EQ(a->objects.size(), 5u);
  ASSERT_EQ(a->cameras.size(), 12u);
  std::map<int, size_t> counts;
  for (uint16_t id : a->instance_ids) ++counts[id];
  for (const SynthObject& o : a->objects) {
    EXPECT_EQ(counts[o.id], o.num_gaussians);
    for (size_t i = o.first_gaussian; i < o.first_gaussian + o.num_gaussians; ++i) ASSERT_EQ(a->instance_ids[i], o.id);
  }
  // The first three are identical bottles standing in a touching row.
  EXPECT_EQ(a->objects[0].duplicate_group, 0);
  EXPECT_EQ(a->objects[2].duplicate_group, 0);
  EXPECT_EQ(a->objects[1].appearance.color_a, a->objects[0].appearance.color_a);
  options->seed = 2;
  absl::StatusOr<ClutterScene> c = GenerateClutterScene(*options);
  ASSERT_TRUE(c.ok());
  EXPECT_NE(c->cloud.positions, a->cloud.positions);
}

TEST(ClutterScene, EveryObjectIsVisibleAndSurfacesAreOpaque) {
  absl::StatusOr<ClutterScene> scene = GenerateClutterScene(*ClutterPreset("tiny"));
  ASSERT_TRUE(scene.ok());
  std::vector<float> ids(scene->instance_ids.begin(), scene->instance_ids.end());
  RenderOptions options;
  options.features = ids.data();
  options.feature_dim = 1;
  std::map<int, int> seen;
  double alpha_sum = 0;
  for (const PinholeCamera& camera : scene->cameras) {
    absl::StatusOr<RenderResult> r = Render(scene->cloud, camera, options);
    ASSERT_TRUE(r.ok());
    for (size_t p = 0; p < r->alpha.size(); ++p) {
      alpha_sum += r->alpha[p];
      const float id = r->features[p] / std::max(r->alpha[p], 1e-6f);
      if (r->alpha[p] > 0.9f && std::abs(id - std::round(id)) < 0.01f) ++seen[static_cast<int>(std::round(id))];
    }
  }
  // The table, floor and wall fill the views: nearly every pixel is opaque.
  EXPECT_GT(alpha_sum / (scene->cameras.size() * 96.0 * 72.0), 0.97);
  for (const SynthObject& o : scene->objects) EXPECT_GT(seen[o.id], 20) << o.name;
}

TEST(ClutterScene, RejectsBadOptionsAndScalesTheTable) {
  ClutterOptions options;
  options.objects = 0;
  EXPECT_FALSE(GenerateClutterScene(options).ok());
  options.objects = 201;
  EXPECT_FALSE(GenerateClutterScene(options).ok());
  options.objects = 150;  // the table grows with the object count, so many objects still fit
  options.gaussians = 100000;
  absl::StatusOr<ClutterScene> crowded = GenerateClutterScene(options);
  ASSERT_TRUE(crowded.ok()) << crowded.status();
  EXPECT_EQ(crowded->objects.size(), 150u);
  EXPECT_FALSE(ClutterPreset("huge").ok());
}

}  // namespace
}  // namespace instascene
