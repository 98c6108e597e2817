#include "services/generation/observed_surface.h"

#include <cmath>

#include <gtest/gtest.h>

namespace instascene::generation {
namespace {

constexpr float kSpacing = 0.01f;

// Observed surfels on a 21 x 21 grid in the plane z = 0, kSpacing apart, seen from +z.
std::vector<Eigen::Vector3f> Patch() {
  std::vector<Eigen::Vector3f> points;
  for (int i = -10; i <= 10; ++i) {
    for (int j = -10; j <= 10; ++j) points.emplace_back(i * kSpacing, j * kSpacing, 0.0f);
  }
  return points;
}

// The patch's normals point -z in storage: with no views, turning them away from a centre below
// the patch gives +z.
class ObservedSurfaceTest : public ::testing::Test {
 protected:
  ObservedSurface Surface(const ObservedSurfaceOptions& options) const {
    return ObservedSurface(&index_,
                           std::vector<Eigen::Vector3f>(index_.size(), -Eigen::Vector3f::UnitZ()),
                           nullptr, Eigen::Vector3f(0, 0, -1), kSpacing, options);
  }
  const PointIndex3 index_{Patch()};
};

TEST_F(ObservedSurfaceTest, RefusesCandidatesInFrontOfOrDeepBehindTheSeenSide) {
  const ObservedSurface surface = Surface(ObservedSurfaceOptions{});
  EXPECT_FALSE(surface.Contradicts({0.003f, 0.0f, 0.005f}));  // on the layer (half a spacing)
  EXPECT_TRUE(surface.Contradicts({0.003f, 0.0f, 0.01f}));    // a spacing in front
  EXPECT_TRUE(surface.Contradicts({0.0f, 0.004f, 0.03f}));    // three spacings in front
  EXPECT_FALSE(surface.Contradicts({0.0f, 0.0f, -0.01f}));    // a wall's other side, 1 spacing
  EXPECT_TRUE(surface.Contradicts({0.0f, 0.0f, -0.02f}));     // inside, past a thin wall
  EXPECT_FALSE(surface.Contradicts({0.0f, 0.0f, -0.06f}));    // a thick solid's far side
  // Beside the patch (its edge at x = 0.1): off the surfels' planes, nothing was seen there.
  EXPECT_FALSE(surface.Contradicts({0.125f, 0.0f, 0.01f}));
  EXPECT_TRUE(surface.Contradicts({0.115f, 0.0f, 0.01f}));
}

// The symmetry search's alignment cost asks the front half only (symmetry.h,
// cost_observed_surface): behind a seen surfel is where a box's unseen face lies beside the edge
// of the seen face next to it.
TEST_F(ObservedSurfaceTest, InFrontOfTheSeenSurfaceIsTheFrontHalfOfTheTest) {
  const ObservedSurface surface = Surface(ObservedSurfaceOptions{});
  EXPECT_TRUE(surface.InFrontOfSeenSurface({0.003f, 0.0f, 0.01f}));  // a spacing in front
  EXPECT_TRUE(surface.InFrontOfSeenSurface({0.0f, 0.004f, 0.02f}));  // two spacings in front
  // Only surfels within front + lateral spacings are asked (2.75 here).
  EXPECT_FALSE(surface.InFrontOfSeenSurface({0.0f, 0.004f, 0.03f}));
  EXPECT_FALSE(surface.InFrontOfSeenSurface({0.003f, 0.0f, 0.005f}));  // on the layer
  EXPECT_FALSE(surface.InFrontOfSeenSurface({0.0f, 0.0f, -0.02f}));    // behind: Contradicts only
  EXPECT_TRUE(surface.Contradicts({0.0f, 0.0f, -0.02f}));
  EXPECT_FALSE(surface.InFrontOfSeenSurface({0.125f, 0.0f, 0.01f}));  // beside the patch
}

TEST_F(ObservedSurfaceTest, ZeroBehindTestsTheFrontOnlyAndZeroFrontTurnsTheTestOff) {
  ObservedSurfaceOptions options;
  options.behind_spacings = 0;
  ASSERT_TRUE(options.Validate().ok());
  const ObservedSurface front_only = Surface(options);
  EXPECT_TRUE(front_only.Contradicts({0.0f, 0.0f, 0.01f}));
  EXPECT_FALSE(front_only.Contradicts({0.0f, 0.0f, -0.02f}));
  options = {};
  options.front_spacings = 0;
  ASSERT_TRUE(options.Validate().ok());
  const ObservedSurface off = Surface(options);
  EXPECT_FALSE(off.Contradicts({0.0f, 0.0f, 0.03f}));
  EXPECT_FALSE(off.InFrontOfSeenSurface({0.0f, 0.0f, 0.03f}));
  EXPECT_FALSE(off.Contradicts({0.0f, 0.0f, -0.02f}));
}

TEST(ObservedSurface, WithoutViewsNormalsTurnAwayFromTheCentre) {
  const std::vector<Eigen::Vector3f> points = {{1, 0, 0}, {-1, 0, 0}};
  const std::vector<Eigen::Vector3f> normals = {{-1, 0, 0}, {-1, 0, 0}};
  const std::vector<Eigen::Vector3f> seen =
      SeenSideNormals(points, normals, nullptr, Eigen::Vector3f::Zero());
  EXPECT_EQ(seen[0], Eigen::Vector3f(1, 0, 0));
  EXPECT_EQ(seen[1], Eigen::Vector3f(-1, 0, 0));
}

TEST(ObservedSurface, OptionsOutOfRangeAreRefused) {
  ObservedSurfaceOptions options;
  options.front_spacings = -1;
  EXPECT_FALSE(options.Validate().ok());
  options = {};
  options.lateral_spacings = 0;
  EXPECT_FALSE(options.Validate().ok());
  options = {};
  options.behind_spacings = std::nanf("");
  EXPECT_FALSE(options.Validate().ok());
}

}  // namespace
}  // namespace instascene::generation
