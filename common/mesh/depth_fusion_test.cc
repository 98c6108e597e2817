// Depth fusion (common/mesh/depth_fusion.h): open and closed surfaces from ring depth maps, the
// closing's gap, the inset, silhouette carving, the visual hull, the support plane.
#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>

#include <gtest/gtest.h>

#include "common/geometry/camera.h"
#include "common/mesh/depth_fusion.h"
#include "common/mesh/mesh_checks.h"
#include "common/mesh/ray_caster.h"
#include "common/synth/primitives.h"

namespace instascene {
namespace {

TriangleMesh Sphere(float radius) { return MakeCenteredSphere(radius, 48); }

// Ring depth maps of `mesh` at 12 azimuths x `elevations` (camera-z depth by ray casting, 0 where
// nothing is hit).
std::vector<DepthView> RingDepthMaps(const TriangleMesh& mesh,
                                     const std::vector<double>& elevations) {
  auto caster = RayCaster::Create(mesh);
  EXPECT_TRUE(caster.ok());
  std::vector<DepthView> views;
  for (int k = 0; k < 12; ++k) {
    for (double elevation : elevations) {
      DepthView view;
      view.camera = OrbitCamera({0, 0, 0}, {0, 0, 1}, 2.0, 30.0 * k, elevation, 64, 64, 50.0);
      const Eigen::Vector3f center = view.camera.CenterInWorld().cast<float>();
      const Eigen::Vector3d forward = view.camera.camera_from_world.rotation.row(2).transpose();
      view.depth.assign(64 * 64, 0.0f);
      for (int row = 0; row < 64; ++row) {
        for (int col = 0; col < 64; ++col) {
          const Eigen::Vector3d ray = view.camera.PixelRayInWorld(col, row);
          const RayHit hit = (*caster)->Cast(center, ray.cast<float>());
          if (hit.hit) view.depth[row * 64 + col] = hit.distance * ray.dot(forward);
        }
      }
      views.push_back(std::move(view));
    }
  }
  return views;
}

// Closed fusion over the cube around a sphere of radius 0.5, 0.02 voxels.
DepthFusionOptions ClosedAroundUnitSphere() {
  DepthFusionOptions options;
  options.voxel = 0.02f;
  options.depth_trunc = 4.0f;
  options.closed_bounds =
      Eigen::AlignedBox3f(Eigen::Vector3f::Constant(-0.55f), Eigen::Vector3f::Constant(0.55f));
  return options;
}

// Sphere(radius) without the triangles whose centroid lies within `hole` of its top.
TriangleMesh SphereWithHole(float radius, float hole) {
  const TriangleMesh sphere = Sphere(radius);
  TriangleMesh holed = sphere;
  holed.triangles.clear();
  for (const auto& t : sphere.triangles) {
    const Eigen::Vector3f c =
        (sphere.vertices[t[0]] + sphere.vertices[t[1]] + sphere.vertices[t[2]]) / 3;
    if ((c - Eigen::Vector3f(0, 0, radius)).norm() > hole) holed.triangles.push_back(t);
  }
  return holed;
}

// A sphere with a hole 5 voxels wide in its top: the open fusion sees the inside through the hole
// and leaves open inner surfaces; the closed fusion gives one closed surface around a solid
// inside, true to the sphere where it was seen, and refuses bad bounds.
TEST(DepthFusion, ClosesTheSurfaceOverHolesAndUnseenSpace) {
  const float radius = 0.5f;
  const TriangleMesh holed = SphereWithHole(radius, 0.05f);
  ASSERT_LT(holed.triangles.size(), Sphere(radius).triangles.size());
  const std::vector<DepthView> views = RingDepthMaps(holed, {-40.0, 0.0, 40.0, 80.0});
  DepthFusionOptions options;
  options.voxel = 0.02f;
  options.depth_trunc = 4.0f;
  auto open = FuseDepthMaps(views, options);
  ASSERT_TRUE(open.ok()) << open.status();
  EXPECT_FALSE(IsClosedManifold(*open));
  options.closed_bounds =
      Eigen::AlignedBox3f(Eigen::Vector3f::Constant(-0.55f), Eigen::Vector3f::Constant(0.55f));
  auto closed = FuseDepthMaps(views, options);
  ASSERT_TRUE(closed.ok()) << closed.status();
  EXPECT_TRUE(IsClosedManifold(*closed));
  ASSERT_EQ(closed->colors.size(), closed->vertices.size());
  double error = 0;
  for (const Eigen::Vector3f& v : closed->vertices) error += std::abs(v.norm() - radius);
  EXPECT_LT(error / closed->vertices.size(), 0.5 * options.voxel);
  // Solid: a line through the centre crosses the surface twice, the hole's axis included.
  auto caster = RayCaster::Create(*closed);
  ASSERT_TRUE(caster.ok());
  for (const Eigen::Vector3f& d : {Eigen::Vector3f(0, 0, -1), Eigen::Vector3f(0, -1, 0)}) {
    EXPECT_EQ((*caster)->CountCrossings(-2.0f * d + Eigen::Vector3f(0.01f, 0.02f, 0.0f), d), 2)
        << d.transpose();
  }
  // A support plane at z = -0.2: nothing below it, and still closed (capped at the plane).
  options.outside_below = Eigen::Vector4f(0, 0, 1, -0.2f);
  auto cut = FuseDepthMaps(views, options);
  ASSERT_TRUE(cut.ok()) << cut.status();
  EXPECT_TRUE(IsClosedManifold(*cut));
  float lowest = 1;
  for (const Eigen::Vector3f& v : cut->vertices) lowest = std::min(lowest, v.z());
  EXPECT_GT(lowest, -0.2f - options.voxel);
  EXPECT_LT(lowest, -0.2f + options.voxel);
  // Bounds far larger than the voxel: the grid keeps its size limit, the voxel grows.
  options.outside_below.setZero();
  options.closed_bounds =
      Eigen::AlignedBox3f(Eigen::Vector3f::Constant(-1e6f), Eigen::Vector3f::Constant(1e6f));
  options.max_closed_resolution = 16;
  EXPECT_TRUE(FuseDepthMaps(views, options).ok());
  options.max_closed_resolution = 4;
  EXPECT_EQ(FuseDepthMaps(views, options).status().code(), absl::StatusCode::kInvalidArgument);
  options.max_closed_resolution = 16;
  options.closed_gap_voxels = -1;
  EXPECT_EQ(FuseDepthMaps(views, options).status().code(), absl::StatusCode::kInvalidArgument);
}

// A hole 12 voxels wide: the outside flows through it at closed_gap_voxels 4 (the inside turns
// hollow: four crossings on a line through the centre beside the hole), not at 8 (solid: two).
TEST(DepthFusion, AWiderGapRuleKeepsAWiderHoleClosed) {
  const std::vector<DepthView> views =
      RingDepthMaps(SphereWithHole(0.5f, 0.12f), {-40.0, 0.0, 40.0, 80.0});
  DepthFusionOptions options = ClosedAroundUnitSphere();
  for (int gap : {4, 8}) {
    options.closed_gap_voxels = gap;
    auto mesh = FuseDepthMaps(views, options);
    ASSERT_TRUE(mesh.ok()) << mesh.status();
    auto caster = RayCaster::Create(*mesh);
    ASSERT_TRUE(caster.ok());
    const int crossings =
        (*caster)->CountCrossings(Eigen::Vector3f(-2.0f, 0.01f, 0.02f), Eigen::Vector3f(1, 0, 0));
    if (gap == 4) {
      EXPECT_GT(crossings, 2) << "gap " << gap;
    } else {
      EXPECT_EQ(crossings, 2) << "gap " << gap;
    }
  }
}

// The inset moves the closed surface inward (a sphere fused from a ring of views shrinks by 0.4-1x
// the inset: the projective TSDF is steeper than the true distance where the views met it
// obliquely) and keeps it closed; beyond half the truncation band it is refused.
TEST(DepthFusion, TheInsetMovesTheClosedSurfaceInward) {
  const float radius = 0.5f;
  const std::vector<DepthView> views = RingDepthMaps(Sphere(radius), {-40.0, 0.0, 40.0, 80.0});
  DepthFusionOptions options = ClosedAroundUnitSphere();
  for (float inset : {0.0f, 0.03f}) {
    options.inset = inset;
    auto mesh = FuseDepthMaps(views, options);
    ASSERT_TRUE(mesh.ok()) << mesh.status();
    EXPECT_TRUE(IsClosedManifold(*mesh));
    double mean = 0;
    for (const Eigen::Vector3f& v : mesh->vertices) mean += v.norm();
    mean /= mesh->vertices.size();
    if (inset == 0) {
      EXPECT_NEAR(mean, radius, 0.25 * options.voxel);
    } else {
      EXPECT_LT(mean, radius - 0.4 * inset);
      EXPECT_GT(mean, radius - inset);
    }
  }
  for (float bad : {-0.01f, 0.051f, std::numeric_limits<float>::quiet_NaN()}) {
    options.inset = bad;  // the band is 5 voxels = 0.1: half of it is 0.05
    EXPECT_EQ(FuseDepthMaps(views, options).status().code(), absl::StatusCode::kInvalidArgument)
        << bad;
  }
}

// Each view's empty pixels (no depth) with their distance in pixels to the nearest pixel with
// depth, by brute force (DepthView::empty_distance_px).
void AddEmptyDistances(std::vector<DepthView>* views) {
  for (DepthView& view : *views) {
    const int w = view.camera.width, h = view.camera.height;
    std::vector<int> filled;
    for (int i = 0; i < w * h; ++i) {
      if (view.depth[i] > 0) filled.push_back(i);
    }
    view.empty_distance_px.assign(view.depth.size(), 0.0f);
    for (int i = 0; i < w * h; ++i) {
      if (view.depth[i] > 0) continue;
      int best = std::numeric_limits<int>::max();
      for (int j : filled) {
        const int dx = i % w - j % w, dy = i / w - j / w;
        best = std::min(best, dx * dx + dy * dy);
      }
      view.empty_distance_px[i] = std::sqrt(static_cast<float>(best));
    }
  }
}

// A sphere with a thin brim (a disc of radius 0.58 in its equator's plane, which the views at
// elevation 0 see edge-on, i.e. not at all, and the views above and below see as surface): depth
// maps alone fuse the brim into a lip; silhouette carving from two views removes it, leaves the
// sphere where it was (carving never lowers a value) and keeps the surface closed.
TEST(DepthFusion, SilhouetteCarvingRemovesALipTheSideViewsSeePast) {
  const float radius = 0.5f, brim = 0.58f;
  TriangleMesh shape = Sphere(radius);
  const uint32_t centre = static_cast<uint32_t>(shape.vertices.size());
  shape.vertices.emplace_back(0, 0, 0);
  constexpr int kRim = 96;
  for (int k = 0; k < kRim; ++k) {
    const float a = 2.0f * static_cast<float>(M_PI) * k / kRim;
    shape.vertices.emplace_back(brim * std::cos(a), brim * std::sin(a), 0.0f);
  }
  for (int k = 0; k < kRim; ++k) {
    const uint32_t a = centre + 1 + k, b = centre + 1 + (k + 1) % kRim;
    shape.triangles.push_back({centre, a, b});
    shape.triangles.push_back({centre, b, a});
  }
  std::vector<DepthView> views = RingDepthMaps(shape, {-40.0, 0.0, 40.0, 80.0});
  AddEmptyDistances(&views);
  DepthFusionOptions options = ClosedAroundUnitSphere();
  options.closed_bounds =
      Eigen::AlignedBox3f(Eigen::Vector3f::Constant(-0.62f), Eigen::Vector3f::Constant(0.62f));
  auto widest = [](const TriangleMesh& mesh) {
    float r = 0;
    for (const Eigen::Vector3f& v : mesh.vertices) r = std::max(r, v.head<2>().norm());
    return r;
  };
  auto lipped = FuseDepthMaps(views, options);
  ASSERT_TRUE(lipped.ok()) << lipped.status();
  EXPECT_GT(widest(*lipped), radius + 3 * options.voxel);
  options.carve_views = 2;
  auto carved = FuseDepthMaps(views, options);
  ASSERT_TRUE(carved.ok()) << carved.status();
  EXPECT_TRUE(IsClosedManifold(*carved));
  EXPECT_LT(widest(*carved), radius + 1.5f * options.voxel);  // a pixel there is 2 voxels
  double error = 0;
  for (const Eigen::Vector3f& v : carved->vertices) error += std::abs(v.norm() - radius);
  EXPECT_LT(error / carved->vertices.size(), 0.5 * options.voxel);
  options.carve_views = -1;
  EXPECT_EQ(FuseDepthMaps(views, options).status().code(), absl::StatusCode::kInvalidArgument);
  options.carve_views = 2;
  views[3].empty_distance_px.pop_back();
  EXPECT_EQ(FuseDepthMaps(views, options).status().code(), absl::StatusCode::kInvalidArgument);
}

// A hole of radius 0.3 (15 voxels) turns the closed sphere hollow at closed_gap_voxels 4, carving,
// when no depth comes from the inner side seen through it. With `seen_empty` the space no depth map
// reached inside the renders' visual hull is inside: solid again; where the capture saw it empty (a
// cup's cavity) it stays open.
TEST(DepthFusion, TheVisualHullKeepsAHoledShellSolid) {
  const TriangleMesh holed = SphereWithHole(0.5f, 0.3f);
  std::vector<DepthView> views = RingDepthMaps(holed, {-40.0, 0.0, 40.0, 80.0});
  AddEmptyDistances(&views);
  // As the meshing renders do (MeshingOptions::cull_inner_sides): no depth from the inner side
  // seen through the hole; the pixel still shows the object.
  auto shell = RayCaster::Create(holed);
  ASSERT_TRUE(shell.ok());
  for (DepthView& view : views) {
    const Eigen::Vector3f eye = view.camera.CenterInWorld().cast<float>();
    for (int i = 0; i < 64 * 64; ++i) {
      const Eigen::Vector3f ray = view.camera.PixelRayInWorld(i % 64, i / 64).cast<float>();
      const RayHit hit = (*shell)->Cast(eye, ray);
      if (hit.hit && hit.normal.dot(ray) > 0) view.depth[i] = 0.0f;
    }
  }
  DepthFusionOptions options = ClosedAroundUnitSphere();
  options.closed_gap_voxels = 4;
  options.carve_views = 2;
  auto crossings = [&](std::function<bool(const Eigen::Vector3f&)> seen_empty) {
    options.seen_empty = std::move(seen_empty);
    auto mesh = FuseDepthMaps(views, options);
    EXPECT_TRUE(mesh.ok()) << mesh.status();
    if (!mesh.ok()) return -1;
    EXPECT_TRUE(IsClosedManifold(*mesh));
    auto caster = RayCaster::Create(*mesh);
    EXPECT_TRUE(caster.ok());
    return caster.ok() ? (*caster)->CountCrossings(Eigen::Vector3f(-2.0f, 0.01f, 0.02f),
                                                   Eigen::Vector3f(1, 0, 0))
                       : -1;
  };
  EXPECT_GT(crossings({}), 2);
  EXPECT_EQ(crossings([](const Eigen::Vector3f&) { return false; }), 2);
  // The capture saw the inside and the opening above it empty: open (a cup's cavity).
  EXPECT_GT(crossings([](const Eigen::Vector3f& p) {
              return p.norm() < 0.4f || (p.z() > 0 && p.head<2>().norm() < 0.25f);
            }),
            2);
}

// An object standing on its support: nothing lies below the support plane (outside_below), even
// where the renders' visual hull reaches under it (the renders show the object's underside there,
// and the capture saw nothing under the table). The hull once kept those voxels blocked, the
// closing's flood could not reach the space under the object, and a slab below the plane meshed
// as inside (a box 7 mm too tall).
TEST(DepthFusion, NothingBelowTheSupportWhateverTheVisualHull) {
  std::vector<DepthView> views = RingDepthMaps(Sphere(0.5f), {0.0, 40.0, 80.0});
  AddEmptyDistances(&views);
  DepthFusionOptions options = ClosedAroundUnitSphere();
  options.closed_gap_voxels = 4;
  options.carve_views = 2;
  options.outside_below << 0, 0, 1, -0.1f;
  for (bool hull : {false, true}) {
    options.seen_empty = hull ? [](const Eigen::Vector3f&) { return false; }
                              : std::function<bool(const Eigen::Vector3f&)>{};
    auto mesh = FuseDepthMaps(views, options);
    ASSERT_TRUE(mesh.ok()) << mesh.status();
    EXPECT_TRUE(IsClosedManifold(*mesh)) << "hull " << hull;
    float lowest = 1;
    for (const Eigen::Vector3f& v : mesh->vertices) lowest = std::min(lowest, v.z());
    EXPECT_GT(lowest, -0.1f - options.voxel) << "hull " << hull;
    EXPECT_LT(lowest, -0.1f + options.voxel) << "hull " << hull;
  }
}

TEST(DepthFusion, ReconstructsASphereFromRingDepthMaps) {
  const float radius = 0.5f;
  std::vector<DepthView> views = RingDepthMaps(Sphere(radius), {-40.0, 0.0, 40.0});
  DepthFusionOptions options;
  options.voxel = 0.02f;
  options.depth_trunc = 4.0f;
  auto fused = FuseDepthMaps(views, options);
  ASSERT_TRUE(fused.ok()) << fused.status();
  ASSERT_GT(fused->triangles.size(), 1000u);
  ASSERT_EQ(fused->colors.size(), fused->vertices.size());
  double error = 0;
  for (const Eigen::Vector3f& v : fused->vertices) error += std::abs(v.norm() - radius);
  EXPECT_LT(error / fused->vertices.size(), 0.5 * options.voxel);
  // Closed: a ray from the centre crosses the surface an odd number of times.
  auto closed = RayCaster::Create(*fused);
  ASSERT_TRUE(closed.ok());
  EXPECT_EQ((*closed)->CountCrossings({0.01f, 0.02f, 0.03f}, {0, 0, 1}) % 2, 1);
  EXPECT_EQ(
      (*closed)->CountCrossings({0.01f, 0.02f, 0.03f}, Eigen::Vector3f(1, 1, 0).normalized()) % 2,
      1);

  options.voxel = 0;
  EXPECT_EQ(FuseDepthMaps(views, options).status().code(), absl::StatusCode::kInvalidArgument);
  options.voxel = 0.02f;
  views[0].depth.pop_back();
  EXPECT_EQ(FuseDepthMaps(views, options).status().code(), absl::StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace instascene
