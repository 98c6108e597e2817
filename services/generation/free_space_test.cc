#include "services/generation/free_space.h"

#include <cmath>

#include <gtest/gtest.h>

#include "common/geometry/camera.h"
#include "common/mesh/ray_caster.h"
#include "common/synth/primitives.h"
#include "services/generation/testing/partial_objects.h"

namespace instascene::generation {
namespace {

using namespace testing;  // NOLINT(build/namespaces): the test scenes

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

}  // namespace
}  // namespace instascene::generation
