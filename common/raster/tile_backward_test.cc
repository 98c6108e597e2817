#include "common/raster/tile_backward.h"

#include <cmath>
#include <cstdio>
#include <functional>
#include <random>

#include <gtest/gtest.h>

#include "common/raster/rasterizer.h"
#include "common/raster/testing/random_surfels.h"

namespace instascene {
namespace {

using testing::RandomSurfels;  // 2-4 m in front of Camera(), 3-8 px wide
PinholeCamera Camera() { return testing::SmallCamera(); }

RenderOptions Options() {
  RenderOptions o;
  for (float& b : o.background) b = 1.0f;
  o.near_plane = 0.01f;
  return o;
}

struct Weights {
  std::vector<float> color, alpha;
};

Weights RandomWeights(uint64_t seed, size_t pixels) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  Weights w;
  w.color.resize(3 * pixels);
  w.alpha.resize(pixels);
  for (float& v : w.color) v = u(rng);
  for (float& v : w.alpha) v = u(rng);
  return w;
}

// ||a - b|| / ||b|| over one parameter array.
double RelativeError(const std::vector<float>& a, const std::vector<float>& b) {
  double diff = 0, norm = 0;
  for (size_t i = 0; i < a.size(); ++i) {
    diff += (a[i] - b[i]) * double(a[i] - b[i]);
    norm += b[i] * double(b[i]);
  }
  return std::sqrt(diff / std::max(norm, 1e-30));
}

// Central differences of `loss` for every value of one parameter array of `cloud`.
std::vector<float> CentralDifferences(const GaussianCloud& cloud,
                                      std::vector<float> GaussianCloud::*field, float eps,
                                      const std::function<double(const GaussianCloud&)>& loss) {
  std::vector<float> out((cloud.*field).size());
  for (size_t k = 0; k < out.size(); ++k) {
    GaussianCloud plus = cloud, minus = cloud;
    (plus.*field)[k] += eps;
    (minus.*field)[k] -= eps;
    out[k] = static_cast<float>((loss(plus) - loss(minus)) / (2 * eps));
  }
  return out;
}

// The slow double-precision kernel (itself checked against finite differences for every
// parameter) is the reference. The models differ only in the low-pass filter's centre and in
// float vs double, so the gradients agree to a small relative error per parameter kind.
TEST(TileBackward, MatchesTheReferenceKernel) {
  double worst[5] = {0, 0, 0, 0, 0};
  for (int scene = 0; scene < 8; ++scene) {
    const GaussianCloud cloud = RandomSurfels(200 + scene, 10, scene % 2);
    const PinholeCamera camera = Camera();
    const Weights w = RandomWeights(300 + scene, 40 * 30);
    auto forward = RenderForBackward(cloud, camera, Options());
    ASSERT_TRUE(forward.ok()) << forward.status();
    auto fast = TileBackward(cloud, camera, Options(), *forward, w.color, w.alpha);
    ASSERT_TRUE(fast.ok()) << fast.status();
    SurfelRenderOptions slow_options;
    slow_options.near_plane = 0.01f;
    auto slow = SurfelBackward(cloud, camera, slow_options, w.color, w.alpha);
    ASSERT_TRUE(slow.ok());
    const double errors[5] = {RelativeError(fast->positions, slow->positions),
                              RelativeError(fast->log_scales, slow->log_scales),
                              RelativeError(fast->rotations, slow->rotations),
                              RelativeError(fast->opacity_logits, slow->opacity_logits),
                              RelativeError(fast->sh, slow->sh)};
    for (int k = 0; k < 5; ++k) worst[k] = std::max(worst[k], errors[k]);
  }
  std::printf(
      "relative error vs reference: position %.2e log-scale %.2e rotation %.2e "
      "opacity %.2e sh %.2e\n",
      worst[0], worst[1], worst[2], worst[3], worst[4]);
  for (double e : worst) EXPECT_LT(e, 3e-2);
}

// Degree-3 SH (the reference stops at degree 1): central differences of the production forward
// for every SH coefficient (the colour is linear in them) and every position (through the view
// direction and the geometry). The surfels are wide enough to cover the whole image with alpha
// above 1/255, so no cut-off lies next to the evaluation point for a difference to straddle.
TEST(TileBackward, MatchesFiniteDifferencesWithDegree3Colour) {
  GaussianCloud cloud = RandomSurfels(7, 3, 3);
  for (float& s : cloud.log_scales) s += std::log(8.0f);
  for (int g = 0; g < 3; ++g) {  // roughly facing the camera: no plane crosses the camera's
    for (int k = 1; k < 4; ++k) cloud.rotations[4 * g + k] *= 0.2f;
  }
  const PinholeCamera camera = Camera();
  const Weights w = RandomWeights(8, 40 * 30);
  RenderOptions options = Options();
  auto forward = RenderForBackward(cloud, camera, options);
  ASSERT_TRUE(forward.ok());
  auto grad = TileBackward(cloud, camera, options, *forward, w.color, w.alpha);
  ASSERT_TRUE(grad.ok());
  auto loss = [&](const GaussianCloud& c) {
    auto r = Render(c, camera, options);
    double sum = 0;
    for (size_t i = 0; i < r->alpha.size(); ++i) {
      sum += w.alpha[i] * double(r->alpha[i]);
      for (int ch = 0; ch < 3; ++ch) sum += w.color[3 * i + ch] * double(r->color[3 * i + ch]);
    }
    return sum;
  };
  auto numeric = [&](std::vector<float> GaussianCloud::*field, float eps) {
    return CentralDifferences(cloud, field, eps, loss);
  };
  const double sh_error = RelativeError(grad->sh, numeric(&GaussianCloud::sh, 0.05f));
  const double pos_error =
      RelativeError(grad->positions, numeric(&GaussianCloud::positions, 2e-3f));
  std::printf("relative error vs finite differences: sh %.2e position %.2e\n", sh_error, pos_error);
  EXPECT_LT(sh_error, 1e-3);
  EXPECT_LT(pos_error, 3e-2);
}

// The normal and median-depth images (the depth-normal consistency term): central differences of
// the production forward for every geometric parameter and opacity. Surfels roughly facing the
// camera and wide enough that their 3-sigma boxes and alpha >= 1/255 cover the whole image, so no
// cut-off lies near the evaluation point (at 8x the boxes' edges cross the image: steps the
// gradient rightly ignores); the median depth is a
// step where the contributor that crosses T = 0.5 changes, so two scenes keep that contributor
// fixed over the image: faint surfels (T > 0.5 after all of them: the median is the last one's
// depth) and an opaque front surfel (T < 0.5 after it: the median is its depth).
TEST(TileBackward, MatchesFiniteDifferencesForNormalAndMedianDepth) {
  const PinholeCamera camera = Camera();
  const size_t pixels = 40 * 30;
  RenderOptions options = Options();
  options.depth = true;
  options.normal = true;
  for (int scene = 0; scene < 2; ++scene) {
    GaussianCloud cloud = RandomSurfels(40 + scene, 3, 0);
    for (float& s : cloud.log_scales) s += std::log(30.0f);
    for (int g = 0; g < 3; ++g) {
      for (int k = 1; k < 4; ++k) cloud.rotations[4 * g + k] *= 0.2f;
      cloud.opacity_logits[g] = std::log(0.2f / 0.8f);  // opacity 0.2: T > 0.512 after three
    }
    if (scene == 1) {  // the nearest surfel opaque and wide enough to cover the whole image
      int front = 0;
      for (int g = 1; g < 3; ++g) {
        if (cloud.positions[3 * g + 2] < cloud.positions[3 * front + 2]) front = g;
      }
      cloud.opacity_logits[front] = std::log(0.95f / 0.05f);
      cloud.log_scales[2 * front] += std::log(4.0f);
      cloud.log_scales[2 * front + 1] += std::log(4.0f);
    }
    Weights wn = RandomWeights(50 + scene, pixels), wd = RandomWeights(60 + scene, pixels);
    auto forward = RenderForBackward(cloud, camera, options);
    ASSERT_TRUE(forward.ok());
    ImageAdjoints adjoints;
    adjoints.normal = wn.color;
    adjoints.median_depth = wd.alpha;
    auto grad = TileBackward(cloud, camera, options, *forward, adjoints);
    ASSERT_TRUE(grad.ok()) << grad.status();
    auto loss = [&](const GaussianCloud& c) {
      auto r = Render(c, camera, options);
      double sum = 0;
      for (size_t i = 0; i < pixels; ++i) {
        EXPECT_GT(r->median_depth[i], 0.0f) << "a pixel the surfels do not cover";
        sum += wd.alpha[i] * double(r->median_depth[i]);
        for (int ch = 0; ch < 3; ++ch) sum += wn.color[3 * i + ch] * double(r->normal[3 * i + ch]);
      }
      return sum;
    };
    auto numeric = [&](std::vector<float> GaussianCloud::*field, float eps) {
      return CentralDifferences(cloud, field, eps, loss);
    };
    const double errors[4] = {
        RelativeError(grad->positions, numeric(&GaussianCloud::positions, 2e-3f)),
        RelativeError(grad->log_scales, numeric(&GaussianCloud::log_scales, 2e-3f)),
        RelativeError(grad->rotations, numeric(&GaussianCloud::rotations, 2e-3f)),
        RelativeError(grad->opacity_logits, numeric(&GaussianCloud::opacity_logits, 2e-3f))};
    std::printf(
        "scene %d: normal + median depth vs finite differences: position %.2e log-scale %.2e "
        "rotation %.2e opacity %.2e\n",
        scene, errors[0], errors[1], errors[2], errors[3]);
    for (double e : errors) EXPECT_LT(e, 1e-2);
  }
}

// Each adjoint must match its image; an empty one is allowed (no dependence).
TEST(TileBackward, RefusesAdjointsOfTheWrongSize) {
  const GaussianCloud cloud = RandomSurfels(14, 5, 0);
  auto forward = RenderForBackward(cloud, Camera(), Options());
  ASSERT_TRUE(forward.ok());
  const std::vector<float> short_image(10, 0.0f);
  ImageAdjoints bad_normal, bad_median, none;
  bad_normal.normal = short_image;
  bad_median.median_depth = short_image;
  EXPECT_EQ(TileBackward(cloud, Camera(), Options(), *forward, bad_normal).status().code(),
            absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(TileBackward(cloud, Camera(), Options(), *forward, bad_median).status().code(),
            absl::StatusCode::kInvalidArgument);
  auto zero = TileBackward(cloud, Camera(), Options(), *forward, none);
  ASSERT_TRUE(zero.ok());
  for (float g : zero->positions) EXPECT_EQ(g, 0.0f);
}

TEST(TileBackward, DoesNotDependOnTheThreadCount) {
  const GaussianCloud cloud = RandomSurfels(11, 40, 1);
  const Weights w = RandomWeights(12, 40 * 30);
  SurfelGradients results[2];
  for (int t = 0; t < 2; ++t) {
    RenderOptions options = Options();
    options.num_threads = t + 1;
    auto forward = RenderForBackward(cloud, Camera(), options);
    ASSERT_TRUE(forward.ok());
    auto grad = TileBackward(cloud, Camera(), options, *forward, w.color, w.alpha);
    ASSERT_TRUE(grad.ok());
    results[t] = *grad;
  }
  EXPECT_EQ(results[0].positions, results[1].positions);
  EXPECT_EQ(results[0].rotations, results[1].rotations);
  EXPECT_EQ(results[0].sh, results[1].sh);
}

TEST(TileBackward, RefusesAForwardOfAnotherCamera) {
  const GaussianCloud cloud = RandomSurfels(13, 5, 0);
  auto forward = RenderForBackward(cloud, Camera(), Options());
  ASSERT_TRUE(forward.ok());
  PinholeCamera other = Camera();
  other.width = 32;
  const std::vector<float> dc(3 * 32 * 30, 0.0f);
  EXPECT_EQ(TileBackward(cloud, other, Options(), *forward, dc, {}).status().code(),
            absl::StatusCode::kInvalidArgument);
  RenderOptions plain = Options();
  auto untraced = Render(cloud, Camera(), plain);
  ASSERT_TRUE(untraced.ok());
  const std::vector<float> dc2(3 * 40 * 30, 0.0f);
  EXPECT_EQ(TileBackward(cloud, Camera(), plain, *untraced, dc2, {}).status().code(),
            absl::StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace instascene
