#include <algorithm>
#include <cmath>
#include <limits>
#include <random>

#include <gtest/gtest.h>

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

}  // namespace
}  // namespace instascene
