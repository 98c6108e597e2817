#include "services/generation/seen_through.h"

#include <cmath>

#include <gtest/gtest.h>

namespace instascene::generation {
namespace {

// A camera at the origin looking down +z (OpenCV axes), 64 x 64 px, 60 px focal length.
PinholeCamera FrontCamera() {
  PinholeCamera c;
  c.width = c.height = 64;
  c.fx = c.fy = 60;
  c.cx = c.cy = 32;
  return c;
}

float Logit(float opacity) { return std::log(opacity / (1 - opacity)); }

// Surfels facing the camera (identity rotation: normal +z) on a grid over [-extent, extent]^2 at
// depth z, `spacing` apart, each with std-dev `sigma` and the given opacity.
void AddWall(float z, float extent, float spacing, float sigma, float opacity,
             GaussianCloud* cloud) {
  const int n = static_cast<int>(std::round(2 * extent / spacing)) + 1;
  const size_t first = cloud->size();
  GaussianCloud wall;
  wall.num_scales = 2;
  wall.Resize(static_cast<size_t>(n) * n);
  for (int i = 0; i < n; ++i) {
    for (int j = 0; j < n; ++j) {
      const size_t g = static_cast<size_t>(i) * n + j;
      wall.positions[3 * g] = -extent + i * spacing;
      wall.positions[3 * g + 1] = -extent + j * spacing;
      wall.positions[3 * g + 2] = z;
      wall.log_scales[2 * g] = wall.log_scales[2 * g + 1] = std::log(sigma);
      wall.opacity_logits[g] = Logit(opacity);
    }
  }
  if (first == 0) {
    *cloud = wall;
    return;
  }
  auto append = [](std::vector<float>* to, const std::vector<float>& from) {
    to->insert(to->end(), from.begin(), from.end());
  };
  append(&cloud->positions, wall.positions);
  append(&cloud->log_scales, wall.log_scales);
  append(&cloud->rotations, wall.rotations);
  append(&cloud->opacity_logits, wall.opacity_logits);
  append(&cloud->sh, wall.sh);
}

TEST(SeenThrough, AnOpaqueWallHidesWhatIsBehindIt) {
  GaussianCloud scene;
  AddWall(1.0f, 0.3f, 0.01f, 0.01f, 0.95f, &scene);
  const float radius = 0.1f;  // tolerance 0.02 * radius = 2 mm
  auto test = SeenThroughTest::Create({FrontCamera()}, scene, radius, SeenThroughOptions{});
  ASSERT_TRUE(test.ok()) << test.status();
  EXPECT_TRUE(test->SeenThrough({0.0f, 0.0f, 0.5f}));      // in front of the wall: seen empty
  EXPECT_TRUE(test->SeenThrough({0.05f, -0.03f, 0.99f}));  // 1 cm in front: still seen empty
  EXPECT_FALSE(test->SeenThrough({0.0f, 0.0f, 0.999f}));   // within the tolerance of the wall
  EXPECT_FALSE(test->SeenThrough({0.0f, 0.0f, 1.2f}));     // behind it: never seen
  EXPECT_FALSE(test->SeenThrough({2.0f, 0.0f, 0.5f}));     // outside the image
  EXPECT_FALSE(test->SeenThrough({0.0f, 0.0f, -0.5f}));    // behind the camera
  EXPECT_EQ(test->ViewsSeeingThrough({0.0f, 0.0f, 0.5f}, 5), 1);
}

TEST(SeenThrough, SeenSideIsTheSideTheViewsSeeingThePointLookFrom) {
  GaussianCloud scene;
  AddWall(1.0f, 0.3f, 0.01f, 0.01f, 0.95f, &scene);
  auto test = SeenThroughTest::Create({FrontCamera()}, scene, 0.1f, SeenThroughOptions{});
  ASSERT_TRUE(test.ok()) << test.status();
  const Eigen::Vector3f on_wall(0.02f, 0.01f, 1.0f);
  EXPECT_EQ(test->SeenSide(on_wall, Eigen::Vector3f::UnitZ()), -1);  // the camera is at -z
  EXPECT_EQ(test->SeenSide(on_wall, -Eigen::Vector3f::UnitZ()), 1);
  EXPECT_EQ(test->SeenSide({0.0f, 0.0f, 1.2f}, Eigen::Vector3f::UnitZ()), 0);  // hidden
  EXPECT_EQ(test->SeenSide({2.0f, 0.0f, 1.0f}, Eigen::Vector3f::UnitZ()), 0);  // off the image
}

// The transmittance along a ray is the product of (1 - alpha) over the surfels it crosses, alpha
// being each Gaussian's value where the ray meets it (a brute-force sum over the surfels).
TEST(SeenThrough, TransmittanceIsTheProductOverTheCrossedSurfels) {
  GaussianCloud scene;
  scene.num_scales = 2;
  const float sigma = 0.05f;
  const float offsets[3][2] = {{0.01f, 0.0f}, {-0.02f, 0.03f}, {0.0f, -0.04f}};
  scene.Resize(3);
  for (int k = 0; k < 3; ++k) {
    scene.positions[3 * k] = offsets[k][0];
    scene.positions[3 * k + 1] = offsets[k][1];
    scene.positions[3 * k + 2] = 1.0f + 0.2f * k;
    scene.log_scales[2 * k] = scene.log_scales[2 * k + 1] = std::log(sigma);
    scene.opacity_logits[k] = Logit(0.4f + 0.1f * k);
  }
  SeenThroughOptions options;
  options.blocked_below = 0.001f;  // count every crossing
  options.extent_sigma = 3.0f;
  auto test = SeenThroughTest::Create({FrontCamera()}, scene, 0.1f, options);
  ASSERT_TRUE(test.ok()) << test.status();
  double expected = 1;
  for (int k = 0; k < 3; ++k) {
    const double r2 = (offsets[k][0] * offsets[k][0] + offsets[k][1] * offsets[k][1]) /
                      (static_cast<double>(sigma) * sigma);
    expected *= 1 - (0.4 + 0.1 * k) * std::exp(-0.5 * r2);
  }
  const float t = test->Transmittance(Eigen::Vector3f::Zero(), Eigen::Vector3f::UnitZ(), 10.0f);
  EXPECT_NEAR(t, expected, 1e-5);
  // Ending the ray between the surfels counts only those in front.
  const float first = test->Transmittance(Eigen::Vector3f::Zero(), Eigen::Vector3f::UnitZ(), 1.1f);
  EXPECT_NEAR(first, 1 - 0.4 * std::exp(-0.5 * 0.01 * 0.01 / (sigma * sigma)), 1e-5);
}

// A faint layer lets the view see on; two faint layers together stop it (0.7 * 0.7 < 0.5).
TEST(SeenThrough, FaintLayersAttenuateTogether) {
  GaussianCloud one, two;
  AddWall(1.0f, 0.3f, 0.02f, 0.004f, 0.3f, &one);  // discs 1 sigma wide: no overlap between them
  two = one;
  AddWall(1.05f, 0.3f, 0.02f, 0.004f, 0.3f, &two);
  const Eigen::Vector3f behind(0.0f, 0.0f, 1.3f);  // on the surfels' axis: alpha = opacity
  auto thin = SeenThroughTest::Create({FrontCamera()}, one, 0.1f, SeenThroughOptions{});
  auto thick = SeenThroughTest::Create({FrontCamera()}, two, 0.1f, SeenThroughOptions{});
  ASSERT_TRUE(thin.ok() && thick.ok());
  const float t1 = thin->Transmittance(Eigen::Vector3f::Zero(), Eigen::Vector3f::UnitZ(), 2.0f);
  const float t2 = thick->Transmittance(Eigen::Vector3f::Zero(), Eigen::Vector3f::UnitZ(), 2.0f);
  EXPECT_NEAR(t1, 0.7f, 1e-5);
  EXPECT_NEAR(t2, 0.49f, 1e-5);
  // The footprint's other rays pass between the small discs: the view sees through behind one
  // layer, not behind two (the footprint's centre ray is stopped).
  EXPECT_TRUE(thin->SeenThrough(behind));
  EXPECT_FALSE(thick->SeenThrough(behind));
}

// A gap between surfels narrower than a pixel at the wall does not count as seeing through it
// (every ray of the footprint must pass); a gap wider than the footprint does.
TEST(SeenThrough, APointIsSeenThroughOnlyWhenItsWholePixelIs) {
  GaussianCloud scene;
  scene.num_scales = 2;
  // Two opaque half-walls at z = 1 leaving a vertical slit of `gap` around x = 0.
  const float pixel_at_wall = 1.0f / 60.0f;  // one pixel spans 1/60 at depth 1
  for (float gap : {0.4f * pixel_at_wall, 4.0f * pixel_at_wall}) {
    GaussianCloud walls;
    const float sigma = 0.002f;
    walls.num_scales = 2;
    std::vector<Eigen::Vector3f> centres;
    for (float x = 0.5f * gap + sigma; x < 0.06f; x += sigma) {
      for (float y = -0.06f; y < 0.06f; y += sigma) {
        centres.emplace_back(x, y, 1.0f);
        centres.emplace_back(-x, y, 1.0f);
      }
    }
    walls.Resize(centres.size());
    for (size_t g = 0; g < centres.size(); ++g) {
      for (int k = 0; k < 3; ++k) walls.positions[3 * g + k] = centres[g][k];
      walls.log_scales[2 * g] = walls.log_scales[2 * g + 1] = std::log(sigma);
      walls.opacity_logits[g] = Logit(0.99f);
    }
    auto test = SeenThroughTest::Create({FrontCamera()}, walls, 0.1f, SeenThroughOptions{});
    ASSERT_TRUE(test.ok()) << test.status();
    const bool wide = gap > pixel_at_wall;
    EXPECT_EQ(test->SeenThrough({0.0f, 0.0f, 1.5f}), wide) << "gap " << gap;
  }
}

// The rim of a blurred silhouette: the surfels along a wall's edge reach past it by their
// sigma, so a point beside the edge is hidden at 1 sigma in every view, but seen through by the
// stricter count (0.5 sigma) in as many views as look past the edge. A point behind the wall
// stays hidden in both counts.
TEST(SeenThrough, TheStricterCountSeesPastABlurredRimFromEnoughViews) {
  GaussianCloud scene;
  scene.num_scales = 2;
  const float sigma = 0.01f, spacing = 0.005f;
  std::vector<Eigen::Vector3f> centres;  // a half-wall x <= 0 at z = 1
  for (float x = -0.1f; x <= 1e-6f; x += spacing) {
    for (float y = -0.1f; y <= 0.1f; y += spacing) centres.emplace_back(x, y, 1.0f);
  }
  scene.Resize(centres.size());
  for (size_t g = 0; g < centres.size(); ++g) {
    for (int k = 0; k < 3; ++k) scene.positions[3 * g + k] = centres[g][k];
    scene.log_scales[2 * g] = scene.log_scales[2 * g + 1] = std::log(sigma);
    scene.opacity_logits[g] = Logit(0.95f);
  }
  // Four cameras beside each other looking down +z, 640 px with a 600 px focal length (a pixel
  // is 2 mm wide at depth 1.2).
  std::vector<PinholeCamera> cameras;
  for (double y : {-0.02, -0.01, 0.01, 0.02}) {
    PinholeCamera c;
    c.width = c.height = 640;
    c.fx = c.fy = 600;
    c.cx = c.cy = 320;
    c.camera_from_world.translation = Eigen::Vector3d(0, -y, 0);
    cameras.push_back(c);
  }
  const Eigen::Vector3f beside(0.007f, 0.0f, 1.2f);  // its rays cross the wall 0.58 sigma out
  const Eigen::Vector3f behind(-0.03f, 0.0f, 1.2f);
  SeenThroughOptions one_sigma;
  one_sigma.core_views = 0;
  SeenThroughOptions core;  // 0.5 sigma (the default), 4 views
  core.core_views = 4;
  SeenThroughOptions too_many = core;
  too_many.core_views = 5;
  for (const auto& [options, seen] :
       {std::pair{one_sigma, false}, std::pair{core, true}, std::pair{too_many, false}}) {
    auto test = SeenThroughTest::Create(cameras, scene, 0.1f, options);
    ASSERT_TRUE(test.ok()) << test.status();
    EXPECT_EQ(test->SeenThrough(beside), seen) << "core views " << options.core_views;
    EXPECT_FALSE(test->SeenThrough(behind));
    EXPECT_EQ(test->ViewsSeeingThrough(beside, 4), 0);  // at 1 sigma, no view
    if (options.core_views > 0) {
      EXPECT_EQ(test->ViewsSeeingThrough(beside, 4, true), 4);
    }
  }
}

// The rim count: one view is enough where its rays pass the object's own blurred rim right beside
// p (within rim_depth_radii in front of it) and miss the core discs; a ray that slips through a
// gap between the core discs of a surface far in front of p (a hidden back side) is not.
TEST(SeenThrough, TheRimCountSeesBesideARimFromOneViewButNotThroughAGapFarInFront) {
  PinholeCamera camera;
  camera.width = camera.height = 640;
  camera.fx = camera.fy = 600;
  camera.cx = camera.cy = 320;
  auto surfels = [](float spacing, float x_max) {
    GaussianCloud scene;
    scene.num_scales = 2;
    std::vector<Eigen::Vector3f> centres;  // a wall x <= x_max at z = 1
    for (float x = -0.1f; x <= x_max + 1e-6f; x += spacing) {
      for (float y = -0.1f; y <= 0.1f + 1e-6f; y += spacing) centres.emplace_back(x, y, 1.0f);
    }
    scene.Resize(centres.size());
    for (size_t g = 0; g < centres.size(); ++g) {
      for (int k = 0; k < 3; ++k) scene.positions[3 * g + k] = centres[g][k];
      scene.log_scales[2 * g] = scene.log_scales[2 * g + 1] = std::log(0.01f);
      scene.opacity_logits[g] = Logit(0.95f);
    }
    return scene;
  };
  SeenThroughOptions without, with;
  without.rim_depth_radii = 0;
  with.rim_depth_radii = 0.2f;  // 2 cm with a radius of 0.1
  // Beside the edge of a dense half-wall, 5 mm behind its plane: the rays cross the plane 0.7
  // sigma past the edge (hidden at 1 sigma) and only this one view looks there.
  const GaussianCloud half_wall = surfels(0.005f, 0.0f);
  const Eigen::Vector3f beside(0.007f * 1.005f, 0.0f, 1.005f);
  for (const auto& [options, seen] : {std::pair{without, false}, std::pair{with, true}}) {
    auto test = SeenThroughTest::Create({camera}, half_wall, 0.1f, options);
    ASSERT_TRUE(test.ok()) << test.status();
    EXPECT_EQ(test->ViewsSeeingThrough(beside), 0);
    EXPECT_EQ(test->SeenThrough(beside), seen) << options.rim_depth_radii;
    EXPECT_FALSE(test->SeenThrough({-0.03f * 1.2f, 0.0f, 1.2f}));  // behind the wall
  }
  // Behind a sparse wall (14 mm apart: its 0.5 sigma discs leave gaps, its 1 sigma discs none),
  // 20 cm behind its plane, in line with a gap: the core discs let this view through, the rim
  // count does not (the surface that stops it at 1 sigma lies far in front).
  const GaussianCloud sparse = surfels(0.014f, 0.1f);
  const Eigen::Vector3f back(0.007f * 1.2f, 0.007f * 1.2f, 1.2f);
  SeenThroughOptions one_core_view = without;
  one_core_view.core_views = 1;
  auto accident = SeenThroughTest::Create({camera}, sparse, 0.1f, one_core_view);
  ASSERT_TRUE(accident.ok());
  EXPECT_TRUE(accident->SeenThrough(back));  // what one view through the core discs would say
  auto test = SeenThroughTest::Create({camera}, sparse, 0.1f, with);
  ASSERT_TRUE(test.ok());
  EXPECT_EQ(test->ViewsSeeingThrough(back), 0);
  EXPECT_FALSE(test->SeenThrough(back));
}

TEST(SeenThrough, RefusesBadOptionsAndClouds) {
  GaussianCloud scene;
  AddWall(1.0f, 0.1f, 0.01f, 0.01f, 0.9f, &scene);
  SeenThroughOptions bad;
  bad.blocked_below = 1.5f;
  EXPECT_EQ(SeenThroughTest::Create({FrontCamera()}, scene, 0.1f, bad).status().code(),
            absl::StatusCode::kInvalidArgument);
  SeenThroughOptions wide_core;
  wide_core.core_sigma = 1.5f;  // wider than extent_sigma: the discs would not hold it
  EXPECT_EQ(SeenThroughTest::Create({FrontCamera()}, scene, 0.1f, wide_core).status().code(),
            absl::StatusCode::kInvalidArgument);
  SeenThroughOptions deep_rim;
  deep_rim.rim_depth_radii = -0.1f;
  EXPECT_EQ(SeenThroughTest::Create({FrontCamera()}, scene, 0.1f, deep_rim).status().code(),
            absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(SeenThroughTest::Create({FrontCamera()}, scene, 0.0f, {}).status().code(),
            absl::StatusCode::kInvalidArgument);
  GaussianCloud ellipsoids = scene;
  ellipsoids.num_scales = 3;
  EXPECT_EQ(SeenThroughTest::Create({FrontCamera()}, ellipsoids, 0.1f, {}).status().code(),
            absl::StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace instascene::generation
