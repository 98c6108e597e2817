#include "common/mesh/surfel_snap.h"

#include <algorithm>
#include <cmath>
#include <functional>
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

// Surfels on the side of an upright cylinder of radius 1 and height 2 standing on z = 0 (rings
// 0.08 apart, from 0.04 up), normals outward, negated every other surfel.
void CylinderSideSurfels(std::vector<Eigen::Vector3f>* points,
                         std::vector<Eigen::Vector3f>* normals) {
  for (int k = 0; k < 25; ++k) {
    for (int j = 0; j < 78; ++j) {
      const float a = static_cast<float>(2 * M_PI * (j + 0.5f * (k % 2)) / 78);
      const Eigen::Vector3f u(std::cos(a), std::sin(a), 0);
      points->push_back(u + Eigen::Vector3f(0, 0, 0.04f + 0.08f * k));
      normals->push_back((j + k) % 2 ? u : Eigen::Vector3f(-u));
    }
  }
}

TEST(SurfelSnap, AFixedBaseSlidesAcrossItsNormalOntoTheSurfels) {
  // A fused cylinder 0.04 narrow (an inset at its base's sharp edge), its base on z = 0 fixed.
  std::vector<Eigen::Vector3f> points, normals;
  CylinderSideSurfels(&points, &normals);
  std::vector<Eigen::Vector2f> profile = {{0, 0}, {0.5f, 0}};
  for (int i = 0; i <= 8; ++i) profile.emplace_back(0.96f, 0.25f * i);
  profile.emplace_back(0, 2);
  const TriangleMesh start = MakeLathe(profile, 64, false);
  std::vector<uint8_t> fixed(start.vertices.size());
  for (size_t v = 0; v < fixed.size(); ++v) fixed[v] = start.vertices[v].z() <= 0;
  auto rim = [](const TriangleMesh& mesh) {  // the base's widest radius, its lowest height
    float widest = 0, lowest = 1e9f;
    for (const Eigen::Vector3f& v : mesh.vertices) {
      if (std::abs(v.z()) < 1e-6f) widest = std::max(widest, v.head<2>().norm());
      lowest = std::min(lowest, v.z());
    }
    return std::make_pair(widest, lowest);
  };
  TriangleMesh held = start;
  SnapToSurfels(points, normals, Options(), &held, fixed);
  EXPECT_FLOAT_EQ(rim(held).first, 0.96f);  // fixed: the rim stays inside the surfels
  SurfelSnapOptions o = Options();
  o.slide_normal = Eigen::Vector3f::UnitZ();
  TriangleMesh slid = start;
  SnapToSurfels(points, normals, o, &slid, fixed);
  EXPECT_NEAR(rim(slid).first, 1.0f, 0.01f);  // the rim reaches the side's surfels
  EXPECT_EQ(rim(slid).second, 0.0f);          // and the base stays on z = 0, flat
  for (size_t v = 0; v < start.vertices.size(); ++v) {
    if (!fixed[v]) continue;
    EXPECT_EQ(slid.vertices[v].z(), 0.0f);
    // The inside of the base (its normal the slide normal) does not move.
    if (start.vertices[v].head<2>().norm() < 0.6f) {
      EXPECT_EQ(slid.vertices[v], start.vertices[v]);
    }
  }
}

// A cone's side sampled likewise (radius 1 at z = 0, apex at z = 2).
void ConeSideSurfels(std::vector<Eigen::Vector3f>* points, std::vector<Eigen::Vector3f>* normals) {
  for (int k = 0; k < 24; ++k) {
    const float z = 0.04f + 0.08f * k, r = 1.0f - 0.5f * z;
    const int n = static_cast<int>(std::lround(2 * M_PI * r / 0.08));
    for (int j = 0; j < n; ++j) {
      const float a = static_cast<float>(2 * M_PI * (j + 0.5f * (k % 2)) / n);
      const Eigen::Vector3f u =
          Eigen::Vector3f(2 * std::cos(a), 2 * std::sin(a), 1).normalized();  // (H cos, H sin, R)
      points->push_back(Eigen::Vector3f(r * std::cos(a), r * std::sin(a), z));
      normals->push_back((j + k) % 2 ? u : Eigen::Vector3f(-u));
    }
  }
}

// A cone's rim slides out to where its side's surfels meet the base: they all stand above it, on
// a side that narrows upwards, so their layer is extrapolated down to the rim's height.
TEST(SurfelSnap, AConesBaseRimSlidesToWhereItsSideMeetsTheBase) {
  std::vector<Eigen::Vector3f> points, normals;
  ConeSideSurfels(&points, &normals);
  std::vector<Eigen::Vector2f> profile = {{0, 0}, {0.5f, 0}};
  for (int i = 0; i <= 8; ++i) profile.emplace_back(0.96f * (1.0f - i / 8.0f), 0.25f * i * 0.96f);
  const TriangleMesh start = MakeLathe(profile, 64, false);
  std::vector<uint8_t> fixed(start.vertices.size());
  for (size_t v = 0; v < fixed.size(); ++v) fixed[v] = start.vertices[v].z() <= 0;
  SurfelSnapOptions o = Options();
  o.slide_normal = Eigen::Vector3f::UnitZ();
  TriangleMesh slid = start;
  SnapToSurfels(points, normals, o, &slid, fixed);
  float rim = 0;
  for (const Eigen::Vector3f& v : slid.vertices) {
    if (v.z() == 0) rim = std::max(rim, v.head<2>().norm());
  }
  EXPECT_NEAR(rim, 1.0f, 0.012f);
}

// A base's outer ring after the clamps: a fused floor out to radius 0.9 that rounds into the side
// at (0.95, 0.04), the side 0.02 inside the surfels above (r = 0.98 - 0.5 z).
TriangleMesh RoundedBase(const std::function<float(float)>& side_radius) {
  std::vector<Eigen::Vector2f> profile = {{0, 0}, {0.5f, 0}, {0.9f, 0}, {0.95f, 0.04f}};
  for (int i = 0; i < 8; ++i) {
    const float z = 0.12f + 0.2f * i;
    profile.emplace_back(side_radius(z), z);
  }
  profile.emplace_back(0, 1.8f);
  return MakeLathe(profile, 64, false);
}

float WidestAt(const TriangleMesh& mesh, float z) {
  float widest = 0;
  for (const Eigen::Vector3f& v : mesh.vertices) {
    if (std::abs(v.z() - z) < 1e-5f) widest = std::max(widest, v.head<2>().norm());
  }
  return widest;
}

TEST(SurfelSnap, AConesRimExtendsToWhereItsSideMeetsTheSupport) {
  std::vector<Eigen::Vector3f> points, normals;
  ConeSideSurfels(&points, &normals);  // the lowest at z = 0.04, r = 0.98
  const TriangleMesh start = RoundedBase([](float z) { return 0.98f - 0.5f * z; });
  std::vector<uint8_t> rim(start.vertices.size());
  for (size_t v = 0; v < rim.size(); ++v) rim[v] = start.vertices[v].z() <= 0.05f;
  SurfelSnapOptions o = Options();
  o.max_move = 0.15f;
  o.slide_normal = Eigen::Vector3f::UnitZ();
  TriangleMesh extended = start;
  EXPECT_GT(ExtendRimToSide(points, normals, o, &extended, rim), 0u);
  EXPECT_NEAR(WidestAt(extended, 0.0f), 1.0f, 0.012f);    // the floor's ring: 0.9 -> the true 1
  EXPECT_NEAR(WidestAt(extended, 0.04f), 0.98f, 0.012f);  // the corner: 0.95 -> 0.98
  for (size_t v = 0; v < start.vertices.size(); ++v) {
    EXPECT_EQ(extended.vertices[v].z(), start.vertices[v].z());  // heights kept
    if (!rim[v] || start.vertices[v].head<2>().norm() < 0.6f) {
      EXPECT_EQ(extended.vertices[v], start.vertices[v]);  // nothing else moves, nor the inside
    }
  }
  // A foot farther than max_move (the floor's ring, 0.1 inside), or no slide normal: the ring
  // stays; the corner, 0.03 inside, still moves.
  o.max_move = 0.05f;
  TriangleMesh bounded = start;
  ExtendRimToSide(points, normals, o, &bounded, rim);
  EXPECT_NEAR(WidestAt(bounded, 0.0f), 0.9f, 1e-5f);
  EXPECT_NEAR(WidestAt(bounded, 0.04f), 0.98f, 0.012f);
  o.slide_normal = Eigen::Vector3f::Zero();
  TriangleMesh unmoved = start;
  EXPECT_EQ(ExtendRimToSide(points, normals, o, &unmoved, rim), 0u);
}

TEST(SurfelSnap, ARimUnderAVerticalSideOrOneThatWidensUpwardsStays) {
  // A cylinder's side (vertical: the clamps hold such a side to its surfels, and a corner's
  // diagonal move would stand out past a face) and a side that widens upwards (a bowl's foot, a
  // torus's underside: extrapolated down, it would stand out where the true one curves in).
  std::vector<Eigen::Vector3f> cylinder, cylinder_normals, widening, widening_normals;
  CylinderSideSurfels(&cylinder, &cylinder_normals);
  for (int k = 0; k < 24; ++k) {
    const float z = 0.04f + 0.08f * k, r = 0.9f + 0.3f * z;
    const int n = static_cast<int>(std::lround(2 * M_PI * r / 0.08));
    for (int j = 0; j < n; ++j) {
      const float a = static_cast<float>(2 * M_PI * (j + 0.5f * (k % 2)) / n);
      widening.emplace_back(r * std::cos(a), r * std::sin(a), z);
      widening_normals.push_back(Eigen::Vector3f(std::cos(a), std::sin(a), -0.3f).normalized());
    }
  }
  SurfelSnapOptions o = Options();
  o.slide_normal = Eigen::Vector3f::UnitZ();
  const TriangleMesh start = RoundedBase([](float) { return 0.96f; });
  std::vector<uint8_t> rim(start.vertices.size());
  for (size_t v = 0; v < rim.size(); ++v) rim[v] = start.vertices[v].z() <= 0.05f;
  TriangleMesh mesh = start;
  EXPECT_EQ(ExtendRimToSide(cylinder, cylinder_normals, o, &mesh, rim), 0u);
  EXPECT_EQ(ExtendRimToSide(widening, widening_normals, o, &mesh, rim), 0u);
  for (size_t v = 0; v < start.vertices.size(); ++v) EXPECT_EQ(mesh.vertices[v], start.vertices[v]);
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
