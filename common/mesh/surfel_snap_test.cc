#include "common/mesh/surfel_snap.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include <gtest/gtest.h>

#include "common/synth/primitives.h"

namespace instascene {
namespace {

TriangleMesh Sphere(float radius) { return MakeCenteredSphere(radius, 48); }

// Surfel centres on a sphere of `radius` (a Fibonacci lattice) with their normals, negated
// every other surfel (2DGS normals have no sign).
void SphereSurfels(float radius, int n, std::vector<Eigen::Vector3f>* points,
                   std::vector<Eigen::Vector3f>* normals) {
  const float golden = static_cast<float>(M_PI * (3.0 - std::sqrt(5.0)));
  for (int i = 0; i < n; ++i) {
    const float z = 1.0f - 2.0f * (i + 0.5f) / n;
    const float r = std::sqrt(1.0f - z * z);
    const Eigen::Vector3f u(r * std::cos(golden * i), r * std::sin(golden * i), z);
    points->push_back(radius * u);
    normals->push_back(i % 2 ? u : Eigen::Vector3f(-u));
  }
}

constexpr int kSurfels = 2000;  // spacing about 0.08 on the unit sphere

SurfelSnapOptions Options() {
  SurfelSnapOptions o;
  o.radius = 0.24f;
  o.layer = 0.04f;
  o.max_move = 0.1f;
  return o;
}

// Over the vertices the triangles use (the sphere's poles are duplicated and unused).
std::pair<float, float> RadiusRange(const TriangleMesh& mesh) {
  float lo = 1e9f, hi = 0;
  for (const auto& t : mesh.triangles) {
    for (uint32_t v : t) {
      lo = std::min(lo, mesh.vertices[v].norm());
      hi = std::max(hi, mesh.vertices[v].norm());
    }
  }
  return {lo, hi};
}

size_t UsedVertices(const TriangleMesh& mesh) {
  std::vector<uint8_t> used(mesh.vertices.size(), 0);
  for (const auto& t : mesh.triangles) {
    for (uint32_t v : t) used[v] = 1;
  }
  return std::count(used.begin(), used.end(), 1);
}

TEST(SurfelSnap, AnInflatedOrShrunkenSphereLandsOnItsSurfels) {
  std::vector<Eigen::Vector3f> points, normals;
  SphereSurfels(1.0f, kSurfels, &points, &normals);
  for (float start : {1.05f, 0.96f}) {
    TriangleMesh mesh = Sphere(start);
    EXPECT_EQ(SnapToSurfels(points, normals, Options(), &mesh), UsedVertices(mesh));
    const auto [lo, hi] = RadiusRange(mesh);
    EXPECT_GT(lo, 0.985f) << start;
    EXPECT_LT(hi, 1.01f) << start;
  }
}

TEST(SurfelSnap, TheOuterSideOfAThinWallIsNotPulledIntoIt) {
  // A shell 0.85 spacings thick (a cup's wall): its outer and inner surfels face the same way.
  std::vector<Eigen::Vector3f> points, normals;
  SphereSurfels(1.0f, kSurfels, &points, &normals);
  SphereSurfels(0.933f, kSurfels, &points, &normals);
  TriangleMesh mesh = Sphere(1.04f);
  SnapToSurfels(points, normals, Options(), &mesh);
  const auto [lo, hi] = RadiusRange(mesh);
  EXPECT_GT(lo, 0.985f);
  EXPECT_LT(hi, 1.01f);
}

TEST(SurfelSnap, TwoStraySurfelsDoNotHoldTheSurfaceOut) {
  std::vector<Eigen::Vector3f> points, normals;
  SphereSurfels(1.0f, kSurfels, &points, &normals);
  // Two surfels of a neighbour 0.05 outside (a touching object's, labelled as this one).
  for (float dy : {-0.04f, 0.04f}) {
    points.push_back(Eigen::Vector3f(1.05f, dy, 0));
    normals.push_back(Eigen::Vector3f::UnitX());
  }
  TriangleMesh mesh = Sphere(1.05f);
  SnapToSurfels(points, normals, Options(), &mesh);
  EXPECT_LT(RadiusRange(mesh).second, 1.01f);
}

TEST(SurfelSnap, MovesAreBoundedAndFixedVerticesOrASurfaceWithoutSurfelsStay) {
  std::vector<Eigen::Vector3f> points, normals;
  SphereSurfels(1.0f, kSurfels, &points, &normals);
  TriangleMesh far = Sphere(1.2f);
  SurfelSnapOptions o = Options();
  o.radius = 0.5f;  // reaches the surfels, but the move is bounded
  SnapToSurfels(points, normals, o, &far);
  EXPECT_GT(RadiusRange(far).first, 1.2f - o.max_move - 1e-4f);
  TriangleMesh held = Sphere(1.05f);  // the lower half fixed (a base on its support)
  std::vector<uint8_t> fixed(held.vertices.size());
  for (size_t v = 0; v < fixed.size(); ++v) fixed[v] = held.vertices[v].z() < 0;
  const TriangleMesh unheld = held;
  SnapToSurfels(points, normals, Options(), &held, fixed);
  for (const auto& t : held.triangles) {
    for (uint32_t v : t) {
      if (fixed[v]) {
        EXPECT_EQ(held.vertices[v], unheld.vertices[v]);
      } else if (held.vertices[v].z() > 0.3f) {
        EXPECT_LT(held.vertices[v].norm(), 1.01f);
      }
    }
  }
  TriangleMesh alone = Sphere(2.0f);  // no surfel within the radius
  const TriangleMesh before = alone;
  EXPECT_EQ(SnapToSurfels(points, normals, Options(), &alone), 0u);
  EXPECT_EQ(alone.vertices, before.vertices);
}

TEST(SurfelSnap, PastTheSurfelsEdgeTheReachPullsTheSurfaceBack) {
  // Surfels only on the cap z > 0.5; the mesh the whole sphere. Without a reach the uncovered
  // part stays; with one, it comes towards the cap by up to max_move, and the cap stays put.
  std::vector<Eigen::Vector3f> all, all_normals, points, normals;
  SphereSurfels(1.0f, kSurfels, &all, &all_normals);
  for (size_t i = 0; i < all.size(); ++i) {
    if (all[i].z() > 0.5f) {
      points.push_back(all[i]);
      normals.push_back(all_normals[i]);
    }
  }
  auto lowest = [](const TriangleMesh& mesh) {
    float z = 1e9f;
    for (const auto& t : mesh.triangles) {
      for (uint32_t v : t) z = std::min(z, mesh.vertices[v].z());
    }
    return z;
  };
  SurfelSnapOptions o = Options();
  TriangleMesh kept = Sphere(1.0f);
  SnapToSurfels(points, normals, o, &kept);
  EXPECT_LT(lowest(kept), -0.999f);
  o.reach = 0.06f;
  TriangleMesh pulled = Sphere(1.0f);
  SnapToSurfels(points, normals, o, &pulled);
  EXPECT_GT(lowest(pulled), -1.0f + 0.8f * o.max_move);
  EXPECT_LE(lowest(pulled), -1.0f + o.max_move + 1e-4f);
  for (const auto& t : pulled.triangles) {
    for (uint32_t v : t) {
      if (pulled.vertices[v].z() > 0.6f) {
        EXPECT_NEAR(pulled.vertices[v].norm(), 1.0f, 0.015f);
      }
    }
  }
}

}  // namespace
}  // namespace instascene
