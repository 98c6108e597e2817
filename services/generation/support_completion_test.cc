#include "services/generation/support_completion.h"

#include <algorithm>
#include <cmath>

#include <gtest/gtest.h>

#include "common/mesh/ray_caster.h"
#include "common/synth/primitives.h"
#include "services/generation/free_space.h"
#include "services/generation/testing/partial_objects.h"

namespace instascene::generation {
namespace {

using namespace testing;  // NOLINT(build/namespaces): the test scenes

// The lowest band seen of a sphere resting on its support (latitudes -50 to -35 degrees, normals
// leaning down 35-50 degrees): straight down, its walls stand a skirt up to 11 mm outside the
// sphere; down their own slope (a tangent, so within 4 mm of it) they never move
// outwards, whichever way the normals point. The upper band (widening downwards) and a
// cylinder's walls (horizontal normals) go straight down either way.
TEST(SupportCompletion, WallsLeaningDownFollowTheirSlope) {
  ObjectFrame frame;
  frame.center = Eigen::Vector3f(0, 0, 0.05f);
  frame.radius = 0.05f;
  frame.has_support = true;
  frame.support_height = 0.0f;
  frame.spacing = 0.003f;
  auto band = [&](bool sphere) {
    std::vector<Eigen::Vector3f> positions;
    std::vector<Eigen::Matrix3f> rotations;
    std::vector<uint32_t> sources;
    for (float latitude = -50; latitude <= -35; latitude += 3) {
      const float phi = latitude * kPi / 180;
      for (int k = 0; k < 60; ++k) {
        const float a = 2 * kPi * k / 60;
        const Eigen::Vector3f radial(std::cos(a), std::sin(a), 0);
        const Eigen::Vector3f n =
            sphere
                ? Eigen::Vector3f(std::cos(phi) * radial + std::sin(phi) * Eigen::Vector3f::UnitZ())
                : radial;
        const Eigen::Vector3f p =
            sphere ? Eigen::Vector3f(frame.center + frame.radius * n)
                   : Eigen::Vector3f(0.03f * radial + Eigen::Vector3f(0, 0, 0.05f + 0.02f * phi));
        Eigen::Matrix3f r;
        const Eigen::Vector3f u = Eigen::Vector3f::UnitZ().cross(n).normalized();
        r << u, n.cross(u), n;
        positions.push_back(p);
        rotations.push_back(r);
        sources.push_back(static_cast<uint32_t>(sources.size()));
      }
    }
    return std::make_tuple(positions, rotations, sources);
  };
  const auto [positions, rotations, sources] = band(true);
  const std::vector<SurfelCandidate> straight = WallExtension(positions, rotations, sources, frame);
  const std::vector<SurfelCandidate> sloped =
      WallExtension(positions, rotations, sources, frame, 0.26f);
  ASSERT_FALSE(straight.empty());
  ASSERT_EQ(sloped.size(), straight.size());
  auto off_sphere = [&](const SurfelCandidate& c) {
    return (c.position - frame.center).norm() - frame.radius;
  };
  auto horizontal = [](const Eigen::Vector3f& p) { return std::hypot(p.x(), p.y()); };
  float worst_straight = 0, worst_sloped = 0;
  for (size_t i = 0; i < straight.size(); ++i) {
    worst_straight = std::max(worst_straight, std::abs(off_sphere(straight[i])));
    worst_sloped = std::max(worst_sloped, std::abs(off_sphere(sloped[i])));
    EXPECT_LE(horizontal(sloped[i].position), horizontal(positions[sloped[i].source]) + 1e-6f);
  }
  EXPECT_GT(worst_straight, 0.010f);
  EXPECT_LT(worst_sloped, 0.005f);
  // About the ball's vertical axis: along its curvature, on the ball, down to the support.
  const std::vector<SurfelCandidate> curved = WallExtension(
      positions, rotations, sources, frame, 0.26f, Eigen::Vector3f(0.0f, 0.0f, 0.02f));
  ASSERT_FALSE(curved.empty());
  float worst_curved = 0, lowest = 1;
  for (const SurfelCandidate& c : curved) {
    worst_curved = std::max(worst_curved, std::abs(off_sphere(c)));
    lowest = std::min(lowest, c.position.z());
    // The candidate's normal is the ball's.
    EXPECT_GT(std::abs(c.rotation.col(2).dot((c.position - frame.center).normalized())), 0.999f);
  }
  EXPECT_LT(worst_curved, 1e-4f);
  EXPECT_LT(lowest, 0.004f);
  // Whichever way the normals point (2DGS surfels carry no outside): the same candidates.
  std::vector<Eigen::Matrix3f> flipped = rotations;
  for (Eigen::Matrix3f& r : flipped) r.col(2) = -r.col(2);
  const std::vector<SurfelCandidate> flipped_sloped =
      WallExtension(positions, flipped, sources, frame, 0.26f);
  ASSERT_EQ(flipped_sloped.size(), sloped.size());
  for (size_t i = 0; i < sloped.size(); ++i) {
    EXPECT_TRUE(flipped_sloped[i].position.isApprox(sloped[i].position));
  }
  // The upper band of the same sphere as the lowest seen (a shoulder: it widens downwards) goes
  // straight down, either sign of normal.
  std::vector<Eigen::Vector3f> upper = positions;
  std::vector<Eigen::Matrix3f> upper_rotations = rotations, upper_flipped = flipped;
  for (size_t i = 0; i < upper.size(); ++i) {
    upper[i].z() = 2 * frame.center.z() - upper[i].z();
    for (Eigen::Matrix3f* r : {&upper_rotations[i], &upper_flipped[i]}) r->row(2) = -r->row(2);
  }
  const std::vector<SurfelCandidate> shoulder =
      WallExtension(upper, upper_rotations, sources, frame);
  for (const auto& rs : {upper_rotations, upper_flipped}) {
    const std::vector<SurfelCandidate> c = WallExtension(upper, rs, sources, frame, 0.26f);
    ASSERT_EQ(c.size(), shoulder.size());
    for (size_t i = 0; i < c.size(); ++i) EXPECT_TRUE(c[i].position.isApprox(shoulder[i].position));
  }
  const auto [walls, wall_rotations, wall_sources] = band(false);
  const std::vector<SurfelCandidate> a = WallExtension(walls, wall_rotations, wall_sources, frame);
  const std::vector<SurfelCandidate> b =
      WallExtension(walls, wall_rotations, wall_sources, frame, 0.26f);
  ASSERT_EQ(a.size(), b.size());
  ASSERT_FALSE(a.empty());
  for (size_t i = 0; i < a.size(); ++i) EXPECT_TRUE(a[i].position.isApprox(b[i].position));
}

// The support cap fills the footprint of the lower walls and stops at them: a cylinder's wall of
// surfels (radius 5 cm, 4 mm apart) gets a cap that covers the inside and reaches the wall but
// not past it (the cap's cells are 1.5 spacings; a rim cell's surfel at the cell's centre, where
// `rim_inside_walls` is off, stood up to half a cell past the wall: seed 42's l-block_5 was 3 mm
// too wide so).
TEST(SupportCompletion, TheCapFillsTheFootprintWithoutOverhangingTheWalls) {
  ObjectFrame frame;
  frame.center = Eigen::Vector3f(0.2f, -0.1f, 0.05f);
  frame.radius = 0.08f;
  frame.has_support = true;
  frame.support_height = 0.0f;
  frame.spacing = 0.004f;
  const float wall = 0.05f;
  std::vector<Eigen::Vector3f> positions;
  std::vector<uint32_t> sources;
  const int around = static_cast<int>(2 * M_PI * wall / frame.spacing);
  for (float z = 0.002f; z < 0.1f; z += frame.spacing) {
    for (int k = 0; k < around; ++k) {
      const double a = 2 * M_PI * k / around;
      positions.push_back(frame.center + Eigen::Vector3f(wall * std::cos(a), wall * std::sin(a),
                                                         z - frame.center.z()));
      sources.push_back(static_cast<uint32_t>(sources.size()));
    }
  }
  auto caster = RayCaster::Create(MakeRectangle(0.1f, 0.1f, 2, 2));
  ASSERT_TRUE(caster.ok());
  auto grid = FreeSpaceGrid::Carve({}, **caster, frame, FreeSpaceOptions{});  // nothing seen
  ASSERT_TRUE(grid.ok()) << grid.status();
  const float cell = 1.5f * frame.spacing;
  const double disc_cells = M_PI * wall * wall / (cell * cell);  // the disc's area in cells
  auto widest = [&](bool rim_inside_walls) {
    const std::vector<SurfelCandidate> cap =
        SupportCap(positions, sources, frame, *grid, rim_inside_walls);
    EXPECT_GT(cap.size(), 0.9 * disc_cells);
    EXPECT_LT(cap.size(), 1.25 * disc_cells);
    float out = 0;
    for (const SurfelCandidate& c : cap) {
      const Eigen::Vector3f q = c.position - frame.center;
      out = std::max(out, std::hypot(q.x(), q.y()));
      EXPECT_NEAR(c.position.z(), 0.25f * frame.spacing, 1e-5f);
    }
    return out;
  };
  const float inside = widest(true), centres = widest(false);
  EXPECT_LE(inside, wall + 0.1f * cell);
  EXPECT_GE(inside, wall - 0.5f * cell);
  EXPECT_GT(centres, wall + 0.3f * cell);  // a cell's centre in a cell the wall crosses
}

}  // namespace
}  // namespace instascene::generation
