#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>
#include <random>

#include <gtest/gtest.h>

#include "common/geometry/camera.h"
#include "common/mesh/depth_fusion.h"
#include "common/mesh/mesh_checks.h"
#include "common/mesh/mesh_ply.h"
#include "common/mesh/ray_caster.h"
#include "common/mesh/surface_distance.h"
#include "common/mesh/surfel_mesh.h"
#include "common/synth/primitives.h"

namespace instascene {
namespace {

TriangleMesh Sphere(float radius) { return MakeCenteredSphere(radius, 48); }

// Brute-force Moller-Trumbore over every triangle: the reference for the Embree casts.
float BruteForceDistance(const TriangleMesh& mesh, const Eigen::Vector3f& o,
                         const Eigen::Vector3f& d) {
  float best = std::numeric_limits<float>::infinity();
  for (const auto& t : mesh.triangles) {
    const Eigen::Vector3d a = mesh.vertices[t[0]].cast<double>();
    const Eigen::Vector3d e1 = mesh.vertices[t[1]].cast<double>() - a;
    const Eigen::Vector3d e2 = mesh.vertices[t[2]].cast<double>() - a;
    const Eigen::Vector3d p = d.cast<double>().cross(e2);
    const double det = e1.dot(p);
    if (std::abs(det) < 1e-14) continue;
    const Eigen::Vector3d s = o.cast<double>() - a;
    const double u = s.dot(p) / det;
    const Eigen::Vector3d q = s.cross(e1);
    const double v = d.cast<double>().dot(q) / det;
    const double dist = e2.dot(q) / det;
    if (u < 0 || v < 0 || u + v > 1 || dist < 0) continue;
    best = std::min(best, static_cast<float>(dist));
  }
  return best;
}

TEST(MeshPly, RoundTripsVerticesColoursAndTriangles) {
  TriangleMesh mesh = Sphere(0.3f);
  for (const Eigen::Vector3f& v : mesh.vertices)
    mesh.colors.push_back((v.array() + 0.5f).min(1.0f));
  auto back = ParseMeshPly(EncodeMeshPly(mesh), "sphere.ply");
  ASSERT_TRUE(back.ok()) << back.status();
  ASSERT_EQ(back->vertices.size(), mesh.vertices.size());
  ASSERT_EQ(back->triangles, mesh.triangles);
  ASSERT_EQ(back->colors.size(), mesh.colors.size());
  for (size_t v = 0; v < mesh.vertices.size(); ++v) {
    EXPECT_EQ(back->vertices[v], mesh.vertices[v]);
    EXPECT_NEAR((back->colors[v] - mesh.colors[v]).cwiseAbs().maxCoeff(), 0.0f, 0.501f / 255);
  }
}

TEST(MeshPly, RejectsTruncatedAndOutOfRangeFaces) {
  TriangleMesh mesh = Sphere(0.3f);
  const std::string data = EncodeMeshPly(mesh);
  const auto truncated = ParseMeshPly(data.substr(0, data.size() - 5), "t.ply");
  EXPECT_EQ(truncated.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(truncated.status().message().find("t.ply"), std::string::npos);
  mesh.triangles[7][1] = static_cast<uint32_t>(mesh.vertices.size());
  const auto bad_index = ParseMeshPly(EncodeMeshPly(mesh), "b.ply");
  EXPECT_EQ(bad_index.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(bad_index.status().message().find("face 7"), std::string::npos);
  EXPECT_FALSE(ParseMeshPly("ply\nformat ascii 1.0\nend_header\n", "a.ply").ok());
}

TEST(RayCaster, MatchesBruteForceOnRandomRays) {
  const TriangleMesh mesh = Sphere(0.5f);
  auto caster = RayCaster::Create(mesh);
  ASSERT_TRUE(caster.ok()) << caster.status();
  std::mt19937 rng(5);
  std::normal_distribution<float> normal(0.0f, 1.0f);
  int hits = 0;
  for (int i = 0; i < 300; ++i) {
    const Eigen::Vector3f origin = Eigen::Vector3f(normal(rng), normal(rng), normal(rng)) * 1.5f;
    const Eigen::Vector3f target = Eigen::Vector3f(normal(rng), normal(rng), normal(rng)) * 0.3f;
    const Eigen::Vector3f dir = (target - origin).normalized();
    const RayHit hit = (*caster)->Cast(origin, dir);
    const float reference = BruteForceDistance(mesh, origin, dir);
    ASSERT_EQ(hit.hit, std::isfinite(reference)) << i;
    if (!hit.hit) continue;
    ++hits;
    EXPECT_NEAR(hit.distance, reference, 1e-5f * std::max(1.0f, reference)) << i;
    EXPECT_NEAR(hit.normal.norm(), 1.0f, 1e-5f);
  }
  EXPECT_GT(hits, 200);
}

TEST(RayCaster, NormalsFaceOutwardAndCrossingsHaveParity) {
  auto caster = RayCaster::Create(Sphere(0.5f));
  ASSERT_TRUE(caster.ok());
  const Eigen::Vector3f origin(2, 0.01f, 0.02f), dir(-1, 0, 0);
  const RayHit hit = (*caster)->Cast(origin, dir);
  ASSERT_TRUE(hit.hit);
  EXPECT_NEAR(hit.distance, 1.5f, 0.01f);
  EXPECT_GT(hit.normal.dot(-dir), 0.9f);  // outward normal faces the ray's origin
  EXPECT_EQ((*caster)->CountCrossings(origin, dir), 2);
  EXPECT_EQ((*caster)->CountCrossings(Eigen::Vector3f(0.01f, 0.02f, 0.03f), dir), 1);  // inside
  EXPECT_FALSE((*caster)->Cast(origin, dir, 0, 1.4f).hit);                             // t_far
}

TEST(RayCaster, RejectsBadMeshesAndHandlesEmptyOnes) {
  TriangleMesh bad = Sphere(0.5f);
  bad.triangles[3][2] = 1u << 30;
  EXPECT_EQ(RayCaster::Create(bad).status().code(), absl::StatusCode::kInvalidArgument);
  bad = Sphere(0.5f);
  bad.vertices[2].x() = std::nanf("");
  EXPECT_EQ(RayCaster::Create(bad).status().code(), absl::StatusCode::kInvalidArgument);
  auto empty = RayCaster::Create(TriangleMesh{});
  ASSERT_TRUE(empty.ok());
  EXPECT_FALSE((*empty)->Cast({0, 0, 0}, {1, 0, 0}).hit);
}

TEST(SurfaceDistance, MatchesTheAnalyticDistanceToABoxInsideAndOutside) {
  ShapeSpec spec;
  spec.size = Eigen::Vector3f(0.4f, 0.2f, 0.3f);
  const TriangleMesh mesh = MakeShapeMesh(spec);
  const Eigen::AlignedBox3f box = mesh.Bounds();
  ASSERT_NEAR(box.sizes().x(), 0.4f, 1e-5f);
  auto distance = SurfaceDistance::Create(mesh);
  ASSERT_TRUE(distance.ok()) << distance.status();
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> u(-0.3f, 0.3f);
  std::vector<Eigen::Vector3f> points;
  for (int i = 0; i < 500; ++i)
    points.push_back(box.center() + Eigen::Vector3f(u(rng), u(rng), u(rng)));
  const std::vector<float> d = (*distance)->Distances(points);
  ASSERT_EQ(d.size(), points.size());
  const Eigen::Vector3f half = box.sizes() / 2;
  int inside = 0;
  for (size_t i = 0; i < points.size(); ++i) {
    const Eigen::Vector3f q = (points[i] - box.center()).cwiseAbs();
    const bool in = (q.array() <= half.array()).all();
    inside += in;
    const float reference =
        in ? (half - q).minCoeff() : (q - half).cwiseMax(Eigen::Vector3f::Zero()).norm();
    EXPECT_NEAR(d[i], reference, 1e-5f) << i;
  }
  EXPECT_GT(inside, 50);  // both sides were tested
  EXPECT_GT(points.size() - inside, 50u);
  EXPECT_TRUE((*distance)->Distances({}).empty());
}

TEST(SurfaceDistance, RejectsEmptyAndOutOfRangeMeshes) {
  EXPECT_EQ(SurfaceDistance::Create(TriangleMesh{}).status().code(),
            absl::StatusCode::kInvalidArgument);
  TriangleMesh bad = Sphere(0.5f);
  bad.triangles[3][2] = 1u << 30;
  EXPECT_EQ(SurfaceDistance::Create(bad).status().code(), absl::StatusCode::kInvalidArgument);
}

TEST(SurfelDiscs, OneDiscPerOpaqueSurfelOnItsPlane) {
  GaussianCloud cloud;
  cloud.Resize(2);
  cloud.positions = {0, 0, 1, 5, 5, 5};
  cloud.log_scales = {std::log(0.1f), std::log(0.05f), 0, 0};
  cloud.opacity_logits = {4.0f, -4.0f};  // the second is faint: no occluder
  std::vector<uint32_t> source;
  const TriangleMesh discs = SurfelDiscs(cloud, {}, SurfelDiscOptions{}, &source);
  ASSERT_EQ(discs.triangles.size(), 6u);
  EXPECT_EQ(source, std::vector<uint32_t>(6, 0));
  auto caster = RayCaster::Create(discs);
  ASSERT_TRUE(caster.ok());
  // Identity rotation: the disc lies in the xy plane at z = 1, radius 0.2 along x, 0.1 along y.
  EXPECT_NEAR((*caster)->Cast({0.15f, 0, 3}, {0, 0, -1}).distance, 2.0f, 1e-5f);
  EXPECT_FALSE((*caster)->Cast({0, 0.15f, 3}, {0, 0, -1}).hit);
}

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
