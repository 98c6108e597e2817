#include "services/generation/diffusion/warping.h"

#include <cmath>
#include <cstdio>

#include <gtest/gtest.h>

#include "common/synth/primitives.h"

namespace instascene::generation::diffusion {
namespace {

// A smooth colour of the surface point: what a direct render of a textured object shows.
Eigen::Vector3f Texture(const Eigen::Vector3f& x) {
  return {0.5f + 0.5f * std::sin(9 * x.x()), 0.5f + 0.5f * std::cos(7 * x.y()),
          0.5f + 0.5f * std::sin(8 * x.z())};
}

// The direct render: per pixel the first mesh hit's texture (0 where the ray misses).
std::vector<float> DirectRender(const RayCaster& mesh, const PinholeCamera& camera) {
  std::vector<float> out(static_cast<size_t>(3) * camera.width * camera.height, 0.0f);
  const Eigen::Vector3f eye = camera.CenterInWorld().cast<float>();
  for (int row = 0; row < camera.height; ++row) {
    for (int col = 0; col < camera.width; ++col) {
      const Eigen::Vector3f dir = camera.PixelRayInWorld(col, row).cast<float>();
      const RayHit hit = mesh.Cast(eye, dir);
      if (!hit.hit) continue;
      const Eigen::Vector3f c = Texture(eye + hit.distance * dir);
      for (int k = 0; k < 3; ++k)
        out[(static_cast<size_t>(row) * camera.width + col) * 3 + k] = c[k];
    }
  }
  return out;
}

TriangleMesh Sphere() {
  ShapeSpec spec;
  spec.kind = ShapeKind::kSphere;
  spec.size = {0.3f, 0, 0};
  return MakeShapeMesh(spec, 96);  // centred at (0, 0, 0.3)
}

TEST(Warping, AKnownViewWarpedIntoATargetReproducesItsDirectRender) {
  auto mesh = RayCaster::Create(Sphere());
  ASSERT_TRUE(mesh.ok());
  const Eigen::Vector3d centre(0, 0, 0.3);
  const PinholeCamera known = OrbitCamera(centre, {0, 0, 1}, 1.2, 0, 20, 128, 128, 40);
  const PinholeCamera target = OrbitCamera(centre, {0, 0, 1}, 1.2, 45, 20, 128, 128, 40);
  auto warped = WarpIntoTarget(**mesh, {KnownView{known, DirectRender(**mesh, known)}}, target,
                               WarpOptions{});
  ASSERT_TRUE(warped.ok()) << warped.status();
  const std::vector<float> truth = DirectRender(**mesh, target);
  double se = 0;
  int64_t n = 0;
  const Eigen::Vector3f known_eye = known.CenterInWorld().cast<float>();
  const Eigen::Vector3f target_eye = target.CenterInWorld().cast<float>();
  int64_t written_facing_away = 0, off_sphere = 0;
  for (int row = 0; row < target.height; ++row) {
    for (int col = 0; col < target.width; ++col) {
      const size_t i = static_cast<size_t>(row) * target.width + col;
      if (!warped->known[i]) continue;
      for (int k = 0; k < 3; ++k) {
        const double d = warped->values[3 * i + k] - truth[3 * i + k];
        se += d * d;
        ++n;
      }
      // Every written point faces the known camera (the sphere hides the rest from it).
      const Eigen::Vector3f dir = target.PixelRayInWorld(col, row).cast<float>();
      const Eigen::Vector3f x = target_eye + (*mesh)->Cast(target_eye, dir).distance * dir;
      written_facing_away += (x - centre.cast<float>()).dot(known_eye - x) < -1e-3f;
      // The hit depth (z in the target camera) puts the point on the sphere.
      const Eigen::Vector3f axis =
          target.camera_from_world.rotation.row(2).transpose().cast<float>();
      const Eigen::Vector3f from_depth = target_eye + warped->depth[i] / dir.dot(axis) * dir;
      off_sphere += std::abs((from_depth - centre.cast<float>()).norm() - 0.3f) > 2e-3f;
    }
  }
  const double psnr = 10 * std::log10(1.0 / (se / n));
  std::printf(
      "warp 45 deg: %lld written, %lld unseen by the known view, %lld missed; PSNR %.1f dB\n",
      static_cast<long long>(warped->written), static_cast<long long>(warped->unseen),
      static_cast<long long>(warped->missed), psnr);
  EXPECT_GT(psnr, 40.0);
  EXPECT_GT(warped->written, 2000);
  EXPECT_GT(warped->unseen, 200);  // the part of the sphere only the target sees
  EXPECT_EQ(written_facing_away, 0);
  EXPECT_EQ(off_sphere, 0);
}

TEST(Warping, WritesNothingOnBackFacesOrWhereTheKnownViewIsBlocked) {
  // An open square facing +z seen from below: every hit is a back face.
  auto quad = RayCaster::Create(MakeRectangle(0.5f, 0.5f, 4, 4));
  ASSERT_TRUE(quad.ok());
  const PinholeCamera above = OrbitCamera({0, 0, 0}, {0, 0, 1}, 1.0, 0, 60, 64, 64, 50);
  const PinholeCamera below = OrbitCamera({0, 0, 0}, {0, 0, 1}, 1.0, 0, -60, 64, 64, 50);
  auto back = WarpIntoTarget(**quad, {KnownView{above, std::vector<float>(64 * 64 * 3, 1.0f)}},
                             below, WarpOptions{});
  ASSERT_TRUE(back.ok());
  EXPECT_EQ(back->written, 0);
  EXPECT_GT(back->back_facing, 100);
  // The known camera looks at the square from above, the target from above too but a box stands
  // between the known camera and the square: nothing the box hides is written.
  TriangleMesh scene = MakeRectangle(0.5f, 0.5f, 4, 4);
  ShapeSpec box;
  box.kind = ShapeKind::kBox;
  box.size = {0.2f, 0.2f, 0.2f};
  TriangleMesh blocker = MakeShapeMesh(box);
  float bottom = 1e9f;
  for (const auto& v : blocker.vertices) bottom = std::min(bottom, v.z());
  for (auto& v : blocker.vertices) v += Eigen::Vector3f(0.0f, 0.0f, 0.35f - bottom);
  scene.Append(blocker);
  auto both = RayCaster::Create(scene);
  ASSERT_TRUE(both.ok());
  const PinholeCamera top = OrbitCamera({0, 0, 0}, {0, 0, 1}, 1.0, 0, 89, 64, 64, 50);
  const PinholeCamera side = OrbitCamera({0, 0, 0}, {0, 0, 1}, 1.0, 90, 70, 64, 64, 50);
  auto hidden = WarpIntoTarget(**both, {KnownView{top, std::vector<float>(64 * 64 * 3, 1.0f)}},
                               side, WarpOptions{});
  ASSERT_TRUE(hidden.ok());
  EXPECT_GT(hidden->written, 100);
  EXPECT_GT(hidden->unseen, 20);  // the square's middle, under the box as the top camera sees it
  auto bad =
      WarpIntoTarget(**both, {KnownView{top, std::vector<float>(5, 1.0f)}}, side, WarpOptions{});
  EXPECT_EQ(bad.status().code(), absl::StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace instascene::generation::diffusion
