#include "common/synth/primitives.h"

#include <gtest/gtest.h>

#include <random>

#include "common/geometry/rigid.h"
#include "common/splat/gaussian_cloud.h"
#include "common/synth/surfels.h"

namespace instascene {
namespace {

// Signed volume by the divergence theorem: positive and equal to the analytic volume for a
// closed, outward-oriented mesh.
double SignedVolume(const TriangleMesh& mesh) {
  double v = 0;
  for (const auto& t : mesh.triangles) {
    v += mesh.vertices[t[0]].cast<double>().dot(
             mesh.vertices[t[1]].cast<double>().cross(mesh.vertices[t[2]].cast<double>())) /
         6.0;
  }
  return v;
}

TEST(Primitives, ClosedMeshesHaveTheAnalyticVolume) {
  const double pi = std::numbers::pi;
  EXPECT_NEAR(SignedVolume(MakeShapeMesh({ShapeKind::kBox, {0.2f, 0.3f, 0.4f}})), 0.024, 1e-6);
  EXPECT_NEAR(SignedVolume(MakeShapeMesh({ShapeKind::kCylinder, {0.1f, 0, 0.2f}}, 256)),
              pi * 0.01 * 0.2, 2e-5);
  EXPECT_NEAR(SignedVolume(MakeShapeMesh({ShapeKind::kCone, {0.1f, 0, 0.3f}}, 256)),
              pi * 0.01 * 0.1, 2e-5);
  EXPECT_NEAR(SignedVolume(MakeShapeMesh({ShapeKind::kSphere, {0.1f, 0, 0}}, 256)),
              4.0 / 3 * pi * 1e-3, 2e-5);
  EXPECT_NEAR(SignedVolume(MakeShapeMesh({ShapeKind::kTorus, {0.1f, 0.03f, 0}}, 256)),
              2 * pi * pi * 0.1 * 0.0009, 2e-5);
  for (ShapeKind k : {ShapeKind::kBottle, ShapeKind::kCup, ShapeKind::kBowl}) {
    const TriangleMesh m = MakeShapeMesh({k, {0.05f, 0, 0.15f}});
    EXPECT_GT(SignedVolume(m), 0.0) << ShapeKindName(k);
    EXPECT_NEAR(m.Bounds().min().z(), 0.0f, 1e-6f);
  }
}

TEST(Primitives, AsymmetricShapesAreClosedPartsWithTheirVolumes) {
  // The L-block's two boxes share a face: volumes add up.
  const TriangleMesh l = MakeShapeMesh({ShapeKind::kLBlock, {0.2f, 0.1f, 0.1f}});
  EXPECT_NEAR(SignedVolume(l), 0.2 * 0.04 * 0.1 + 0.07 * 0.06 * 0.055, 1e-6);
  // The mug: the cup plus a handle torus beside it.
  const TriangleMesh cup = MakeShapeMesh({ShapeKind::kCup, {0.05f, 0, 0.1f}}, 96);
  const TriangleMesh mug = MakeShapeMesh({ShapeKind::kMug, {0.05f, 0, 0.1f}}, 96);
  EXPECT_GT(SignedVolume(mug), SignedVolume(cup));
  EXPECT_GT(mug.Bounds().max().x(), cup.Bounds().max().x() + 0.03f);  // the handle sticks out
  // Nothing of the handle hangs inside the cavity (above the floor, within the inner wall).
  const float inner = 0.05f * (1.0f - 0.08f), floor = 0.08f * 0.05f;
  int in_cavity = 0;
  for (const Eigen::Vector3f& v : mug.vertices) {
    in_cavity += v.z() > floor + 1e-5f && std::hypot(v.x(), v.y()) < inner - 1e-5f;
  }
  EXPECT_EQ(in_cavity, 0);
  // The irregular block keeps its base and is closed with a positive volume.
  const TriangleMesh rock = MakeShapeMesh({ShapeKind::kIrregular, {0.15f, 0.1f, 0.1f}});
  EXPECT_GT(SignedVolume(rock), 0.15 * 0.1 * 0.1);
  EXPECT_NEAR(rock.Bounds().min().z(), 0.0f, 1e-6f);
  for (ShapeKind k : {ShapeKind::kMug, ShapeKind::kLBlock, ShapeKind::kIrregular}) {
    EXPECT_NE(ShapeKindName(k), "?");
  }
}

TEST(Surfels, ApicesAreAppendedWithoutChangingTheSampledSurfels) {
  const TriangleMesh cone = MakeShapeMesh({ShapeKind::kCone, {0.04f, 0, 0.09f}});
  GaussianCloud plain, tipped;
  plain.num_scales = tipped.num_scales = 2;
  std::mt19937_64 a(5), b(5);
  AppendSurfels(cone, 300, Appearance{}, SurfelSampling{}, a, &plain);
  const SurfelApex apex{Eigen::Vector3f(0, 0, 0.09f), Eigen::Vector3f::UnitZ(), {0, 1}};
  AppendSurfels(cone, 300, Appearance{}, SurfelSampling{}, b, &tipped, 0.0f, {apex});
  ASSERT_EQ(tipped.size(), 301u);
  ASSERT_TRUE(tipped.Validate().ok());
  EXPECT_EQ(a(), b());  // the apex drew nothing from the generator
  for (size_t k = 0; k < 3 * 300; ++k) ASSERT_EQ(plain.positions[k], tipped.positions[k]);
  EXPECT_EQ(Eigen::Vector3f(&tipped.positions[3 * 300]), apex.position);
  // Sized like its neighbours, facing along its normal.
  EXPECT_EQ(tipped.log_scales[2 * 300], tipped.log_scales[0]);
  const float* q = &tipped.rotations[4 * 300];
  EXPECT_NEAR(RotationFromQuaternionWxyz(q[0], q[1], q[2], q[3]).col(2).z(), 1.0, 1e-6);
}

}  // namespace
}  // namespace instascene
